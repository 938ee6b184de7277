//! Model orders `(na, nb, nk)` in MATLAB's `arx` convention.

use crate::error::LinearError;

/// Orders of a MISO polynomial model with a common denominator.
///
/// - `na`: order of the denominator `A` (ARX) or `F` (OE), i.e. the number of `a`/`f`
///   coefficients after the leading 1;
/// - `nb[i]`: number of numerator coefficients of input `i` (`0` means the input is unused);
/// - `nk[i]`: input delay of input `i` in samples (`0` allowed: direct feedthrough).
///
/// `nb.len() == nk.len()` is the number of inputs.
///
/// ```
/// use structid_linear::Orders;
/// // A = 1 + a1 q^-1 + a2 q^-2,  B = q^-1 (b0 + b1 q^-1)
/// let o = Orders::siso(2, 2, 1);
/// assert_eq!(o.parameters(), 4);
/// assert_eq!(o.inputs(), 1);
/// assert_eq!(o.max_lag(), 2);
/// ```
#[derive(Clone, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Orders {
    /// Denominator order.
    pub na: usize,
    /// Numerator coefficient counts, one per input.
    pub nb: Vec<usize>,
    /// Input delays in samples, one per input.
    pub nk: Vec<usize>,
}

impl Orders {
    /// Orders of a single-input model.
    ///
    /// ```
    /// use structid_linear::Orders;
    /// assert_eq!(Orders::siso(1, 2, 3).nk, vec![3]);
    /// ```
    pub fn siso(na: usize, nb: usize, nk: usize) -> Self {
        Orders {
            na,
            nb: vec![nb],
            nk: vec![nk],
        }
    }

    /// Validated orders of a multi-input model (`nb` and `nk` of equal, nonzero length).
    ///
    /// ```
    /// use structid_linear::Orders;
    /// let o = Orders::new(2, vec![2, 1], vec![1, 0]).unwrap();
    /// assert_eq!(o.parameters(), 5);
    /// assert!(Orders::new(2, vec![2], vec![1, 0]).is_err());
    /// ```
    pub fn new(na: usize, nb: Vec<usize>, nk: Vec<usize>) -> Result<Self, LinearError> {
        let o = Orders { na, nb, nk };
        o.validate()?;
        Ok(o)
    }

    /// Number of estimated parameters `na + Σ nb[i]`.
    ///
    /// ```
    /// use structid_linear::Orders;
    /// assert_eq!(Orders { na: 3, nb: vec![2, 4], nk: vec![0, 1] }.parameters(), 9);
    /// ```
    pub fn parameters(&self) -> usize {
        self.na + self.nb.iter().sum::<usize>()
    }

    /// Number of inputs (`nb.len()`).
    ///
    /// ```
    /// use structid_linear::Orders;
    /// assert_eq!(Orders::siso(1, 1, 0).inputs(), 1);
    /// ```
    pub fn inputs(&self) -> usize {
        self.nb.len()
    }

    /// The largest lag in the model, `max(na, nk[i] + nb[i] − 1)` over inputs with
    /// `nb[i] > 0`: the number of leading samples an ARX regression cannot use.
    ///
    /// ```
    /// use structid_linear::Orders;
    /// assert_eq!(Orders::siso(1, 2, 3).max_lag(), 4);
    /// assert_eq!(Orders::siso(2, 0, 7).max_lag(), 2);
    /// ```
    pub fn max_lag(&self) -> usize {
        self.nb
            .iter()
            .zip(&self.nk)
            .filter(|(b, _)| **b > 0)
            .map(|(b, k)| k + b - 1)
            .fold(self.na, usize::max)
    }

    /// Checks that `nb` and `nk` have the same nonzero length and that at least one
    /// parameter is estimated.
    ///
    /// ```
    /// use structid_linear::Orders;
    /// assert!(Orders::siso(2, 2, 1).validate().is_ok());
    /// assert!(Orders::siso(0, 0, 0).validate().is_err());
    /// ```
    pub fn validate(&self) -> Result<(), LinearError> {
        if self.nb.len() != self.nk.len() {
            return Err(LinearError::InvalidOrders(format!(
                "nb has {} entries but nk has {} (one of each per input)",
                self.nb.len(),
                self.nk.len()
            )));
        }
        if self.nb.is_empty() {
            return Err(LinearError::InvalidOrders(
                "at least one input is needed (nb and nk are empty)".into(),
            ));
        }
        if self.parameters() == 0 {
            return Err(LinearError::InvalidOrders(
                "no parameters to estimate (na = 0 and every nb is 0)".into(),
            ));
        }
        Ok(())
    }
}

impl std::fmt::Display for Orders {
    /// `na=2 nb=[2] nk=[1]`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "na={} nb={:?} nk={:?}", self.na, self.nb, self.nk)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_lags() {
        let o = Orders::new(2, vec![3, 0], vec![2, 5]).unwrap();
        assert_eq!(o.parameters(), 5);
        assert_eq!(o.max_lag(), 4);
        assert_eq!(o.to_string(), "na=2 nb=[3, 0] nk=[2, 5]");
        assert!(Orders::new(1, vec![], vec![]).is_err());
    }
}
