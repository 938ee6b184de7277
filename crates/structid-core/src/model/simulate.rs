//! Simulation of the structured system with static maps in the loop.

use structid_lti::Signal;

use crate::error::{Error, Result};
use crate::model::Model;
use crate::model::interpolant::Interpolant;
use crate::model::lft::Lft;
use crate::model::order::BlockPlace;

/// One static map placed in the loop: `w[output] = map(z[inputs])`.
#[derive(Clone, Copy)]
pub struct MapBinding<'a> {
    /// z channels read by the map.
    pub inputs: &'a [usize],
    /// w channel written.
    pub output: usize,
    /// The map itself (an estimate, a closure, an expression, a table, …).
    pub map: &'a dyn Interpolant,
}

impl<'a> MapBinding<'a> {
    /// One binding per block place (z channels read, w channel written) and map, in order:
    /// how a model's blocks and their maps are put in the loop.
    pub fn zip(
        places: impl IntoIterator<Item = (&'a [usize], usize)>,
        maps: &[&'a dyn Interpolant],
    ) -> Vec<Self> {
        places
            .into_iter()
            .zip(maps)
            .map(|((inputs, output), map)| MapBinding {
                inputs,
                output,
                map: *map,
            })
            .collect()
    }
}

/// Everything a simulation produced.
#[derive(Clone, Debug, PartialEq)]
pub struct Simulation {
    /// Measured outputs y (L × n_y).
    pub y: Signal,
    /// Map inputs z (L × n_z).
    pub z: Signal,
    /// Map outputs w (L × n_w).
    pub w: Signal,
    /// State after the last sample.
    pub final_state: Vec<f64>,
}

fn row_major(m: &nalgebra::DMatrix<f64>) -> Vec<f64> {
    let mut v = Vec::with_capacity(m.len());
    for i in 0..m.nrows() {
        for j in 0..m.ncols() {
            v.push(m[(i, j)]);
        }
    }
    v
}

/// out += M·x for a row-major M (rows × x.len()).
fn gemv_add(m: &[f64], x: &[f64], out: &mut [f64]) {
    let cols = x.len();
    if cols == 0 {
        return;
    }
    for (o, row) in out.iter_mut().zip(m.chunks_exact(cols)) {
        *o += row.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
    }
}

impl Lft {
    /// Simulates the LFT with the given maps in the loop.
    ///
    /// `e` defaults to zero and `x0` to the zero state. Needs a map for every w channel. Maps
    /// in series (D_zw ≠ 0 without a cycle) are evaluated in order within each sample
    /// ([`Lft::evaluation_order`]); a cycle is refused with [`Error::AlgebraicLoop`].
    ///
    /// ```
    /// use nalgebra::dmatrix;
    /// use structid_core::{Lft, LftMatrices, MapBinding};
    /// use structid_lti::Signal;
    /// // y_k = tanh(u_k) + 0.5·y_{k−1}-type loop: x⁺ = 0.5x + w, y = x, z = u.
    /// let lft = Lft::new(LftMatrices {
    ///     a: dmatrix![0.5], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![1.0],
    ///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
    ///     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
    /// }).unwrap();
    /// let tanh = |z: &[f64]| z[0].tanh();
    /// let u = Signal::from_fn(5, 1, |k, _| k as f64);
    /// let sim = lft.simulate(&[MapBinding { inputs: &[0], output: 0, map: &tanh }], &u, None, None).unwrap();
    /// assert!((sim.y.get(1, 0) - 0.0f64.tanh()).abs() < 1e-15);
    /// ```
    pub fn simulate(
        &self,
        maps: &[MapBinding<'_>],
        u: &Signal,
        e: Option<&Signal>,
        x0: Option<&[f64]>,
    ) -> Result<Simulation> {
        let d = self.dims();
        let len = u.len();
        if u.channels() != d.u {
            return Err(Error::DimensionMismatch {
                what: "number of input channels u".into(),
                expected: d.u.to_string(),
                found: u.channels().to_string(),
            });
        }
        let zero_e;
        let e = match e {
            Some(e) => {
                if e.channels() != d.e || e.len() != len {
                    return Err(Error::DimensionMismatch {
                        what: "noise signal e".into(),
                        expected: format!("{len} samples × {} channels", d.e),
                        found: format!("{} samples × {} channels", e.len(), e.channels()),
                    });
                }
                e
            }
            None => {
                zero_e = Signal::zeros(len, d.e);
                &zero_e
            }
        };
        let mut x = match x0 {
            Some(x0) if x0.len() != d.states => {
                return Err(Error::DimensionMismatch {
                    what: "initial state".into(),
                    expected: d.states.to_string(),
                    found: x0.len().to_string(),
                });
            }
            Some(x0) => x0.to_vec(),
            None => vec![0.0; d.states],
        };
        let mut covered = vec![false; d.w];
        for m in maps {
            if m.output >= d.w || m.inputs.iter().any(|&i| i >= d.z) {
                return Err(Error::InvalidStructure(format!(
                    "a map reads z{:?} and writes w[{}], outside the LFT's {} z and {} w signals",
                    m.inputs, m.output, d.z, d.w
                )));
            }
            if covered[m.output] {
                return Err(Error::InvalidStructure(format!(
                    "two maps write w[{}]",
                    m.output
                )));
            }
            covered[m.output] = true;
        }
        if let Some(c) = covered.iter().position(|c| !c) {
            return Err(Error::InvalidStructure(format!(
                "no map given for w[{c}]; simulation needs every static map"
            )));
        }
        let names: Vec<String> = maps.iter().map(|m| format!("w[{}]", m.output)).collect();
        let places: Vec<BlockPlace<'_>> = maps
            .iter()
            .zip(&names)
            .map(|(m, name)| BlockPlace {
                name,
                inputs: m.inputs,
                output: m.output,
            })
            .collect();
        let order = self.evaluation_order(&places)?;
        let mm = self.matrices();
        let [a, bu, be, bw, cy, dyu, dye, dyw, cz, dzu, dze, dzw] = [
            &mm.a, &mm.bu, &mm.be, &mm.bw, &mm.cy, &mm.dyu, &mm.dye, &mm.dyw, &mm.cz, &mm.dzu,
            &mm.dze, &mm.dzw,
        ]
        .map(row_major);
        let series = dzw.iter().any(|v| *v != 0.0);
        let mut y = Signal::zeros(len, d.y);
        let mut z = Signal::zeros(len, d.z);
        let mut w = Signal::zeros(len, d.w);
        let mut xn = vec![0.0; d.states];
        let mut arg = Vec::new();
        let mut zk = vec![0.0; d.z];
        for k in 0..len {
            let (uk, ek) = (u.sample(k), e.sample(k));
            zk.iter_mut().for_each(|v| *v = 0.0);
            gemv_add(&cz, &x, &mut zk);
            gemv_add(&dzu, uk, &mut zk);
            gemv_add(&dze, ek, &mut zk);
            let wk = w.sample_mut(k);
            for &b in &order {
                let m = &maps[b];
                arg.clear();
                // w channels not yet written this sample are zero, and the order guarantees
                // that every channel this map reads through D_zw has been written.
                arg.extend(m.inputs.iter().map(|&i| {
                    let through_w = if series {
                        dzw[i * d.w..(i + 1) * d.w]
                            .iter()
                            .zip(wk.iter())
                            .map(|(a, b)| a * b)
                            .sum()
                    } else {
                        0.0
                    };
                    zk[i] + through_w
                }));
                wk[m.output] = m.map.eval(&arg);
                if !wk[m.output].is_finite() {
                    return Err(Error::Numerical(format!(
                        "the map for w[{}] returned {} at sample {k} (its input {arg:?})",
                        m.output, wk[m.output]
                    )));
                }
            }
            let wk = w.sample(k).to_vec();
            gemv_add(&dzw, &wk, &mut zk);
            z.sample_mut(k).copy_from_slice(&zk);
            let yk = y.sample_mut(k);
            gemv_add(&cy, &x, yk);
            gemv_add(&dyu, uk, yk);
            gemv_add(&dye, ek, yk);
            gemv_add(&dyw, &wk, yk);
            xn.iter_mut().for_each(|v| *v = 0.0);
            gemv_add(&a, &x, &mut xn);
            gemv_add(&bu, uk, &mut xn);
            gemv_add(&be, ek, &mut xn);
            gemv_add(&bw, &wk, &mut xn);
            std::mem::swap(&mut x, &mut xn);
            if x.iter().any(|v| !v.is_finite()) {
                return Err(Error::Unstable(format!(
                    "the simulation diverged: the state became non-finite at sample {k}; the linear \
                     block or the loop through the maps is unstable for this input"
                )));
            }
        }
        Ok(Simulation {
            y,
            z,
            w,
            final_state: x,
        })
    }
}

impl Model {
    /// Simulates the model with one map per block, in the order of [`Model::blocks`].
    pub fn simulate(
        &self,
        maps: &[&dyn Interpolant],
        u: &Signal,
        e: Option<&Signal>,
        x0: Option<&[f64]>,
    ) -> Result<Simulation> {
        if maps.len() != self.blocks().len() {
            return Err(Error::DimensionMismatch {
                what: "number of maps for simulation".into(),
                expected: self.blocks().len().to_string(),
                found: maps.len().to_string(),
            });
        }
        // A cycle is named by the blocks' own names before the LFT's simulation sees it.
        self.evaluation_order()?;
        let places = self
            .blocks()
            .iter()
            .map(|b| (b.inputs.as_slice(), b.output));
        self.lft()
            .simulate(&MapBinding::zip(places, maps), u, e, x0)
    }
}
