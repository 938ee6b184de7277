//! Long records thinned for display without losing their peaks.

/// Thins a series `(x, y)` for display to at most two points per bucket of consecutive
/// samples: each of `buckets` equal runs of indices keeps its smallest and its largest `y` (in
/// their time order, so that a line through them still goes forward), which is what a pixel
/// column of a line plot shows. A spike of a single sample survives; plain every-n-th
/// subsampling would drop it. Series no longer than `2·buckets` are returned whole. Non-finite
/// values are skipped; a bucket that holds no finite value keeps one `NaN`, so that a drawn
/// line is broken there as it would be without thinning. `x` and `y` are cut to the shorter
/// length.
///
/// ```
/// use structid_plot::decimate_min_max;
/// let x: Vec<f64> = (0..100_000).map(|k| k as f64).collect();
/// let mut y: Vec<f64> = x.iter().map(|t| (t * 1e-3).sin()).collect();
/// y[54_321] = 10.0; // one spike
/// let (xd, yd) = decimate_min_max(&x, &y, 1000);
/// assert!(xd.len() <= 2000);
/// assert!(yd.contains(&10.0));
/// ```
pub fn decimate_min_max(x: &[f64], y: &[f64], buckets: usize) -> (Vec<f64>, Vec<f64>) {
    let n = x.len().min(y.len());
    let buckets = buckets.max(1);
    if n <= 2 * buckets {
        return (x[..n].to_vec(), y[..n].to_vec());
    }
    let mut xs = Vec::with_capacity(2 * buckets);
    let mut ys = Vec::with_capacity(2 * buckets);
    for b in 0..buckets {
        let (start, end) = (b * n / buckets, (b + 1) * n / buckets);
        let mut lo: Option<usize> = None;
        let mut hi: Option<usize> = None;
        for k in start..end {
            if !y[k].is_finite() {
                continue;
            }
            if lo.is_none_or(|i| y[k] < y[i]) {
                lo = Some(k);
            }
            if hi.is_none_or(|i| y[k] > y[i]) {
                hi = Some(k);
            }
        }
        match (lo, hi) {
            (Some(a), Some(c)) => {
                let (first, second) = if a <= c { (a, c) } else { (c, a) };
                xs.push(x[first]);
                ys.push(y[first]);
                if second != first {
                    xs.push(x[second]);
                    ys.push(y[second]);
                }
            }
            _ => {
                xs.push(x[start]);
                ys.push(f64::NAN);
            }
        }
    }
    (xs, ys)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Min and max of the finite values of `y[range]`.
    fn envelope(y: &[f64]) -> (f64, f64) {
        y.iter()
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            })
    }

    /// Per bucket, the thinned series has the original's minimum and maximum, at the same
    /// abscissae, in time order.
    #[test]
    fn every_bucket_keeps_its_envelope() {
        let n = 100_000;
        let buckets = 700;
        let x: Vec<f64> = (0..n).map(|k| 0.01 * k as f64).collect();
        // A deterministic rough signal: a slow sine plus a pseudo-random part.
        let mut s = 1u64;
        let y: Vec<f64> = (0..n)
            .map(|k| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (k as f64 * 1e-3).sin() + ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5)
            })
            .collect();
        let (xd, yd) = decimate_min_max(&x, &y, buckets);
        assert!(xd.len() <= 2 * buckets && xd.len() == yd.len());
        assert!(xd.windows(2).all(|w| w[0] < w[1]), "time order kept");
        for b in 0..buckets {
            let (start, end) = (b * n / buckets, (b + 1) * n / buckets);
            let (lo, hi) = (x[start], x[end - 1]);
            let kept: Vec<f64> = xd
                .iter()
                .zip(&yd)
                .filter(|(t, _)| **t >= lo && **t <= hi)
                .map(|(_, v)| *v)
                .collect();
            assert_eq!(envelope(&kept), envelope(&y[start..end]), "bucket {b}");
        }
        // Every kept point is an original sample.
        for (t, v) in xd.iter().zip(&yd) {
            let k = (t / 0.01).round() as usize;
            assert_eq!(y[k], *v);
        }
    }

    #[test]
    fn a_single_spike_survives_and_short_series_stay_whole() {
        let n = 50_000;
        let x: Vec<f64> = (0..n).map(|k| k as f64).collect();
        let mut y = vec![0.0; n];
        y[31_337] = -5.0;
        let (xd, yd) = decimate_min_max(&x, &y, 100);
        let i = yd
            .iter()
            .position(|v| *v == -5.0)
            .expect("the spike is kept");
        assert_eq!(xd[i], 31_337.0);
        let (xs, ys) = decimate_min_max(&x[..150], &y[..150], 100);
        assert_eq!((xs.len(), ys.len()), (150, 150));
    }

    #[test]
    fn gaps_stay_gaps() {
        let x: Vec<f64> = (0..1000).map(|k| k as f64).collect();
        let y: Vec<f64> = (0..1000)
            .map(|k| {
                if (400..600).contains(&k) {
                    f64::NAN
                } else {
                    1.0
                }
            })
            .collect();
        let (_, yd) = decimate_min_max(&x, &y, 10);
        assert_eq!(yd.iter().filter(|v| v.is_nan()).count(), 2);
        assert!(yd.iter().filter(|v| v.is_finite()).all(|v| *v == 1.0));
    }
}
