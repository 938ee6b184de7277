//! The free entries of G as a user names them: `A` (every non-zero entry of A), `Bw[1][0]` or
//! `Bw[1,0]` (one entry).

use structid_joint::{JointModel, LftMatrix};

use crate::error::{Result, WorkflowError};

fn matrix(name: &str) -> Option<LftMatrix> {
    let all = ["A", "Bu", "Bw", "Cy", "Dyu", "Dyw", "Cz", "Dzu", "Dzw"];
    let i = all.iter().position(|m| m.eq_ignore_ascii_case(name))?;
    Some(LftMatrix::ALL[i])
}

/// Frees the entries `specs` name in `model`.
///
/// ```
/// use nalgebra::dmatrix;
/// use structid_core::{Lft, LftMatrices};
/// use structid_joint::{GaussianFeatures, JointBlock, JointModel, LftMatrix};
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![0.5, 0.1; 0.0, 0.3], bu: dmatrix![1.0; 0.0], be: dmatrix![0.0; 0.0],
///     bw: dmatrix![0.0; 1.0], cy: dmatrix![0.0, 1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0],
///     dyw: dmatrix![0.0], cz: dmatrix![1.0, 0.0], dzu: dmatrix![0.0], dze: dmatrix![0.0],
///     dzw: dmatrix![0.0],
/// }).unwrap();
/// let f = GaussianFeatures::on_interval(-1.0, 1.0, 3, 0.5, 0.0).unwrap();
/// let m = JointModel::new(lft, vec![JointBlock::new("N", vec![0], 0, Box::new(f))]).unwrap();
/// let m = structid_workflow::parse_free(m, &["A".into(), "Bu[0][0]".into()]).unwrap();
/// assert_eq!(m.free_entries().len(), 4);
/// assert_eq!(m.free_entries()[3].matrix, LftMatrix::Bu);
/// assert!(structid_workflow::parse_free(m, &["Q[0][0]".into()]).is_err());
/// ```
pub fn parse_free(mut model: JointModel, specs: &[String]) -> Result<JointModel> {
    for spec in specs {
        let s = spec.trim();
        let (name, rest) = s.split_at(s.find('[').unwrap_or(s.len()));
        let bad = |why: &str| {
            WorkflowError::Request(format!(
                "free entry `{spec}`: {why}; name a matrix (A, Bu, Bw, Cy, Dyu, Dyw, Cz, Dzu, Dzw) for \
                 its non-zero entries, or one entry as `Bw[1][0]`"
            ))
        };
        let m = matrix(name).ok_or_else(|| bad("unknown matrix"))?;
        if rest.is_empty() {
            model = model.with_free_nonzero(m)?;
            continue;
        }
        let digits: Vec<&str> = rest
            .split(['[', ']', ','])
            .map(str::trim)
            .filter(|t| !t.is_empty())
            .collect();
        let idx: Vec<usize> = digits
            .iter()
            .map(|t| t.parse::<usize>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| bad("indices must be whole numbers"))?;
        let [row, col] = idx[..] else {
            return Err(bad("give a row and a column"));
        };
        model = model.with_free(m, row, col)?;
    }
    Ok(model)
}
