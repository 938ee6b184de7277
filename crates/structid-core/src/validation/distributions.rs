//! The distributions the residual and comparison tests refer to: the standard normal's tail
//! and quantile, the χ² quantile, and Student's t.

/// The standard normal quantile Φ⁻¹(p) for 0 < p < 1 (Acklam's rational approximation,
/// relative error below 1.2e-9).
///
/// ```
/// let z = structid_core::validation::distributions::normal_quantile(0.99);
/// assert!((z - 2.326_347_874).abs() < 1e-8);
/// ```
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// The `p` quantile of χ² with `k` degrees of freedom (Wilson–Hilferty; within 1 % for k ≥ 5
/// and p ≤ 0.9999).
///
/// ```
/// let q = structid_core::validation::distributions::chi_square_quantile(0.99, 25);
/// assert!((q - 44.31).abs() < 0.3);
/// ```
pub fn chi_square_quantile(p: f64, k: usize) -> f64 {
    let k = k.max(1) as f64;
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + normal_quantile(p) * a.sqrt()).powi(3).max(0.0)
}

/// P(Z ≥ x) for a standard normal Z: erfc(x/√2)/2, by the Chebyshev fit of erfc with a relative
/// error below 1.2·10⁻⁷ everywhere.
pub fn upper_normal_tail(x: f64) -> f64 {
    if x.is_nan() {
        return f64::NAN;
    }
    0.5 * erfc(x / std::f64::consts::SQRT_2)
}

fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let r = t * poly.exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// P(|T| ≤ t) for Student's t with `dof` ≥ 1 degrees of freedom, in closed form (Abramowitz
/// and Stegun 26.7.3–4): with θ = atan(t/√ν), a finite series in cos²θ, even ν summing
/// sin θ·Σ_j c_j cos^{2j}θ and odd ν adding (2/π)·θ.
///
/// ```
/// use structid_core::validation::distributions::student_t_two_sided;
/// // ν = 1 is the Cauchy distribution: P(|T| ≤ 1) = 1/2.
/// assert!((student_t_two_sided(1.0, 1) - 0.5).abs() < 1e-12);
/// ```
pub fn student_t_two_sided(t: f64, dof: usize) -> f64 {
    let nu = dof.max(1);
    let t = t.abs();
    if t.is_nan() {
        return f64::NAN;
    }
    if t.is_infinite() {
        return 1.0;
    }
    let theta = (t / (nu as f64).sqrt()).atan();
    let (s, c2) = (theta.sin(), theta.cos().powi(2));
    // Terms c_j cos^{2j}θ (even ν) or cos^{2j+1}θ (odd ν), each from the last by the ratio
    // (2j − 1)/(2j) or (2j)/(2j + 1).
    if nu.is_multiple_of(2) {
        let mut term = 1.0;
        let mut sum = 1.0;
        for j in 1..nu / 2 {
            term *= c2 * (2 * j - 1) as f64 / (2 * j) as f64;
            sum += term;
        }
        (s * sum).min(1.0)
    } else {
        let mut sum = 0.0;
        if nu > 1 {
            let mut term = theta.cos();
            sum = term;
            for j in 1..(nu - 1) / 2 {
                term *= c2 * (2 * j) as f64 / (2 * j + 1) as f64;
                sum += term;
            }
        }
        (2.0 / std::f64::consts::PI * (theta + s * sum)).min(1.0)
    }
}

/// The `p` quantile of Student's t with `dof` degrees of freedom, for 0.5 ≤ p < 1: the root of
/// (1 + [`student_t_two_sided`])/2 = p, by bisection to a relative width of 1e-12 (0 below
/// p = 0.5, ∞ at p ≥ 1, NaN for NaN).
///
/// ```
/// use structid_core::validation::distributions::student_t_quantile;
/// assert!((student_t_quantile(0.975, 6) - 2.446_912).abs() < 1e-5);
/// ```
pub fn student_t_quantile(p: f64, dof: usize) -> f64 {
    if p.is_nan() {
        return f64::NAN;
    }
    if p <= 0.5 {
        return 0.0;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    let cdf = |t: f64| 0.5 * (1.0 + student_t_two_sided(t, dof));
    let mut hi = 1.0;
    while cdf(hi) < p && hi < 1e300 {
        hi *= 2.0;
    }
    let mut lo = 0.0;
    while hi - lo > 1e-12 * hi {
        let mid = 0.5 * (lo + hi);
        if cdf(mid) < p { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn student_t_matches_the_tables() {
        // Two-sided tables: (ν, p, t).
        for (nu, p, t) in [
            (1, 0.975, 12.706_205),
            (2, 0.975, 4.302_653),
            (2, 0.995, 9.924_843),
            (3, 0.95, 2.353_363),
            (5, 0.99, 3.364_930),
            (6, 0.975, 2.446_912),
            (6, 0.995, 3.707_428),
            (30, 0.975, 2.042_272),
        ] {
            let q = student_t_quantile(p, nu);
            assert!(
                (q - t).abs() < 2e-6 * t,
                "ν = {nu}, p = {p}: {q} against {t}"
            );
        }
        assert!(student_t_quantile(f64::NAN, 3).is_nan());
        assert!(student_t_two_sided(f64::NAN, 3).is_nan());
        // Many degrees of freedom approach the normal.
        let z = normal_quantile(0.975);
        assert!((student_t_quantile(0.975, 2000) - z).abs() < 2e-3);
    }

    #[test]
    fn the_t_distribution_is_a_distribution() {
        for nu in 1..12 {
            let mut last = 0.0;
            for k in 0..200 {
                let a = student_t_two_sided(0.1 * k as f64, nu);
                assert!(a >= last - 1e-15 && a <= 1.0, "ν = {nu}");
                last = a;
            }
            // Odd ν = 1 and 3 against the closed forms 2/π·atan t and
            // 2/π·(θ + sinθ cosθ).
            let t: f64 = 1.7;
            if nu == 1 {
                assert!(
                    (student_t_two_sided(t, 1) - 2.0 / std::f64::consts::PI * t.atan()).abs()
                        < 1e-14
                );
            }
            if nu == 3 {
                let th = (t / 3f64.sqrt()).atan();
                let want = 2.0 / std::f64::consts::PI * (th + th.sin() * th.cos());
                assert!((student_t_two_sided(t, 3) - want).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn the_normal_tail_matches_tabulated_values() {
        for (x, p) in [
            (0.0, 0.5),
            (1.959_963_985, 0.025),
            (-1.959_963_985, 0.975),
            (3.0, 0.001_349_898),
            (-1.0, 0.841_344_746),
        ] {
            assert!((upper_normal_tail(x) - p).abs() < 2e-7 * p.max(1e-3), "{x}");
        }
        assert_eq!(upper_normal_tail(f64::INFINITY), 0.0);
        assert_eq!(upper_normal_tail(f64::NEG_INFINITY), 1.0);
    }

    #[test]
    fn quantiles_match_tabulated_values() {
        assert!((chi_square_quantile(0.99, 51) - 77.386).abs() < 0.3);
        assert!((chi_square_quantile(0.99, 25) - 44.314).abs() < 0.3);
        assert!((normal_quantile(0.975) - 1.959_963_985).abs() < 1e-8);
        assert!((normal_quantile(1e-5) + 4.264_890_794).abs() < 1e-7);
        // The quantile inverts the tail.
        for p in [0.001, 0.2, 0.5, 0.9, 0.999] {
            assert!((upper_normal_tail(-normal_quantile(p)) - p).abs() < 1e-6 * p.max(0.01));
        }
    }
}
