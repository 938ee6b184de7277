//! Which blocks the paper's identification can reach: per block, whether its input z is
//! computable from u and y (Definition 1, [`Lft::measurability`] restricted to the block's z
//! rows), read from another block of the same sample (maps in series), or latent.
//!
//! A model whose blocks are not all computable is not refused as a whole: the report says which
//! blocks need the joint fit by simulation error (`structid-joint`), and why.

use nalgebra::DMatrix;

use crate::error::{Error, Result};
use crate::model::lft::{Lft, LftMatrices};
use crate::model::order::BlockPlace;

/// How the paper's identification reaches one block's input.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BlockAccess {
    /// Its input is computable from u and y.
    Computable,
    /// It reads the outputs of these blocks in the same sample, through D_zw (maps in series).
    InSeries {
        /// The blocks it reads.
        upstream: Vec<String>,
    },
    /// Its input is a signal that u and y do not reveal (an unmeasured state, say), whether or
    /// not it also reads other maps: a latent block.
    Latent,
}

impl BlockAccess {
    /// Whether the paper's identification can reach the block.
    pub fn is_computable(&self) -> bool {
        matches!(self, Self::Computable)
    }
}

fn rows(m: &DMatrix<f64>, r: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(r.len(), m.ncols(), |i, j| m[(r[i], j)])
}

impl Lft {
    /// The LFT restricted to the z rows `inputs`, without their same-sample terms D_zw: the
    /// part of a block's input that u and y must reveal ([module docs](self)).
    pub(crate) fn own_rows(&self, inputs: &[usize]) -> Result<Lft> {
        let m = self.matrices();
        Lft::new(LftMatrices {
            cz: rows(&m.cz, inputs),
            dzu: rows(&m.dzu, inputs),
            dze: rows(&m.dze, inputs),
            dzw: DMatrix::zeros(inputs.len(), self.dims().w),
            ..m.clone()
        })
    }

    /// How each block in `places` is reached (see the [module docs](self)).
    ///
    /// ```
    /// use nalgebra::dmatrix;
    /// use structid_core::{BlockAccess, BlockPlace, Lft, LftMatrices};
    /// // Two tanks, only the lower level x₂ measured: N₁ reads x₁ (latent), N₂ reads y = x₂.
    /// let lft = Lft::new(LftMatrices {
    ///     a: dmatrix![1.0, 0.0; 0.0, 1.0], bu: dmatrix![1.0; 0.0], be: dmatrix![0.0; 0.0],
    ///     bw: dmatrix![-1.0, 0.0; 1.0, -1.0], cy: dmatrix![0.0, 1.0], dyu: dmatrix![0.0],
    ///     dye: dmatrix![1.0], dyw: dmatrix![0.0, 0.0], cz: dmatrix![1.0, 0.0; 0.0, 1.0],
    ///     dzu: dmatrix![0.0; 0.0], dze: dmatrix![0.0; 1.0], dzw: dmatrix![0.0, 0.0; 0.0, 0.0],
    /// }).unwrap();
    /// let places = [
    ///     BlockPlace { name: "upper", inputs: &[0], output: 0 },
    ///     BlockPlace { name: "lower", inputs: &[1], output: 1 },
    /// ];
    /// let access = lft.block_access(&places).unwrap();
    /// assert_eq!(access, vec![BlockAccess::Latent, BlockAccess::Computable]);
    /// ```
    ///
    /// # Errors
    /// Places outside the LFT's channels, or Markov parameters that overflow.
    pub fn block_access(&self, places: &[BlockPlace<'_>]) -> Result<Vec<BlockAccess>> {
        let m = self.matrices();
        let d = self.dims();
        let writer = |col: usize| places.iter().find(|p| p.output == col).map(|p| p.name);
        places
            .iter()
            .map(|p| {
                if let Some(&bad) = p.inputs.iter().find(|&&i| i >= d.z) {
                    return Err(Error::InvalidStructure(format!(
                        "block `{}` reads z[{bad}], and the LFT has {} z channel(s)",
                        p.name, d.z
                    )));
                }
                let mut upstream: Vec<String> = Vec::new();
                for &i in p.inputs {
                    for j in 0..d.w {
                        if m.dzw[(i, j)] != 0.0 {
                            let name = writer(j).map_or(format!("w[{j}]"), str::to_string);
                            if !upstream.contains(&name) {
                                upstream.push(name);
                            }
                        }
                    }
                }
                // The block's own z rows without the same-sample terms of other maps: latent
                // when even these are not computable (in series or not: latent is what needs the
                // smoothed start), in series when only the other maps' outputs are missing.
                match self.own_rows(p.inputs)?.measurability() {
                    Ok(_) if upstream.is_empty() => Ok(BlockAccess::Computable),
                    Ok(_) => Ok(BlockAccess::InSeries { upstream }),
                    Err(Error::NotMeasurable { .. }) => Ok(BlockAccess::Latent),
                    Err(e) => Err(e),
                }
            })
            .collect()
    }

    /// `Ok` when every block's input is computable from u and y; otherwise
    /// [`Error::OutOfReach`] naming each block that is not, and why, and pointing to the
    /// joint fit, which takes them.
    ///
    /// # Errors
    /// As described, and [`Lft::block_access`]'s.
    pub fn check_blocks_computable(&self, places: &[BlockPlace<'_>]) -> Result<()> {
        let access = self.block_access(places)?;
        let why: Vec<String> = places
            .iter()
            .zip(&access)
            .filter_map(|(p, a)| match a {
                BlockAccess::Computable => None,
                BlockAccess::InSeries { upstream } => Some(format!(
                    "block `{}` reads the output of {} in the same sample (maps in series)",
                    p.name,
                    upstream
                        .iter()
                        .map(|u| format!("`{u}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                )),
                BlockAccess::Latent => Some(format!(
                    "block `{}` is latent: its input is a signal that u and y do not reveal",
                    p.name
                )),
            })
            .collect();
        if why.is_empty() {
            return Ok(());
        }
        let blocks = places
            .iter()
            .zip(&access)
            .filter(|(_, a)| **a != BlockAccess::Computable)
            .map(|(p, _)| p.name.to_string())
            .collect();
        Err(Error::OutOfReach {
            blocks,
            explanation: format!(
                "{}. Identification by the dispersion criterion needs every block's input computable \
                 from u and y; the joint fit by simulation error (`structid_joint`) takes maps in \
                 series and latent blocks",
                why.join("; ")
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;

    /// x⁺ = 0.5x + u + w₀ + w₁, y = x + e; a reads u, b reads y and a's output, c reads x
    /// through a path y reveals only with a delay it cannot undo (the state of a second,
    /// unmeasured integrator).
    fn lft() -> Lft {
        Lft::new(LftMatrices {
            a: dmatrix![0.5, 0.0; 1.0, 1.0],
            bu: dmatrix![1.0; 0.0],
            be: dmatrix![0.0; 0.0],
            bw: dmatrix![1.0, 1.0, 0.0; 0.0, 0.0, 0.0],
            cy: dmatrix![1.0, 0.0],
            dyu: dmatrix![0.0],
            dye: dmatrix![1.0],
            dyw: dmatrix![0.0, 0.0, 0.0],
            cz: dmatrix![0.0, 0.0; 1.0, 0.0; 0.0, 1.0],
            dzu: dmatrix![1.0; 0.0; 0.0],
            dze: dmatrix![0.0; 1.0; 0.0],
            dzw: dmatrix![0.0, 0.0, 0.0; 0.7, 0.0, 0.0; 0.0, 0.0, 0.0],
        })
        .unwrap()
    }

    #[test]
    fn each_block_is_reported_computable_in_series_or_latent() {
        let places = [
            BlockPlace {
                name: "a",
                inputs: &[0],
                output: 0,
            },
            BlockPlace {
                name: "b",
                inputs: &[1],
                output: 1,
            },
            BlockPlace {
                name: "c",
                inputs: &[2],
                output: 2,
            },
        ];
        let access = lft().block_access(&places).unwrap();
        assert_eq!(
            access,
            vec![
                BlockAccess::Computable,
                BlockAccess::InSeries {
                    upstream: vec!["a".into()]
                },
                BlockAccess::Latent
            ]
        );
        let e = lft()
            .check_blocks_computable(&places)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("z is not measurable"), "{e}");
        assert!(e.contains("block `b` reads the output of `a`"), "{e}");
        assert!(e.contains("block `c` is latent"), "{e}");
        assert!(e.contains("joint fit") && !e.contains("block `a`"), "{e}");
        // Only the computable block: no error.
        assert!(lft().check_blocks_computable(&places[..1]).is_ok());
        // A block reading a channel the LFT does not have is an error, not a panic.
        let bad = [BlockPlace {
            name: "d",
            inputs: &[5],
            output: 0,
        }];
        assert!(lft().block_access(&bad).is_err());
    }
}
