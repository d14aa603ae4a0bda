//! Statistics for the tests: distributions for deriving thresholds from a stated false-alarm
//! rate, per-element batch statistics, and a chi-square goodness-of-fit test.
#![allow(dead_code)]

/// Complementary error function (Numerical Recipes' Chebyshev fit, relative error < 1.2e-7).
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    // The fit's polynomial in t by Horner's rule, innermost term first (nested, the expression
    // takes rustfmt seconds to lay out).
    let mut p = 0.17087277;
    for c in [-0.82215223, 1.48851587, -1.13520398, 0.27886807, -0.18628806, 0.09678418, 0.37409196, 1.00002368] {
        p = c + t * p;
    }
    let r = t * (-z * z - 1.26551223 + t * p).exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// P(|Z| > z) for a standard normal Z.
pub fn normal_two_sided_p(z: f64) -> f64 {
    erfc(z.abs() / std::f64::consts::SQRT_2)
}

/// ln Gamma(x) (Lanczos).
pub fn ln_gamma(x: f64) -> f64 {
    let c = [
        76.18009172947146,
        -86.50532032941677,
        24.01409824083091,
        -1.231739572450155,
        0.1208650973866179e-2,
        -0.5395239384953e-5,
    ];
    let tmp = x + 5.5 - (x + 0.5) * (x + 5.5).ln();
    let mut ser = 1.000000000190015;
    for (j, cj) in c.iter().enumerate() {
        ser += cj / (x + 1.0 + j as f64);
    }
    -tmp + (2.5066282746310005 * ser / x).ln()
}

/// Regularized upper incomplete gamma Q(a, x).
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    if x < a + 1.0 {
        // series for P
        let (mut sum, mut del, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        1.0 - sum * (-x + a * x.ln() - ln_gamma(a)).exp()
    } else {
        // continued fraction for Q (modified Lentz)
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (-x + a * x.ln() - ln_gamma(a)).exp() * h
    }
}

/// P(X > x) for a chi-square variable with `dof` degrees of freedom.
pub fn chi2_sf(x: f64, dof: f64) -> f64 {
    gamma_q(0.5 * dof, 0.5 * x)
}

/// Regularized incomplete beta I_x(a, b) (continued fraction).
pub fn beta_inc(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let front = (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln()).exp();
    if x < (a + 1.0) / (a + b + 2.0) { front * beta_cf(a, b, x) / a } else { 1.0 - front * beta_cf(b, a, 1.0 - x) / b }
}

fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    let tiny = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < tiny {
        d = tiny;
    }
    d = 1.0 / d;
    let mut h = d;
    // One modified-Lentz step with coefficient aa; returns the factor to multiply h by.
    let mut step = |aa: f64| {
        let clamp = |v: f64| if v.abs() < tiny { tiny } else { v };
        d = 1.0 / clamp(1.0 + aa * d);
        c = clamp(1.0 + aa / c);
        d * c
    };
    for m in 1..10_000 {
        let m = m as f64;
        let m2 = 2.0 * m;
        h *= step(m * (b - m) * x / ((qam + m2) * (a + m2)));
        let del = step(-(a + m) * (qab + m) * x / ((a + m2) * (qap + m2)));
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// P(|T| > t) for Student's t with `dof` degrees of freedom.
pub fn t_two_sided_p(t: f64, dof: f64) -> f64 {
    beta_inc(0.5 * dof, 0.5, dof / (dof + t * t))
}

/// The |t| exceeded with probability `p` (two-sided) by Student's t with `dof` degrees of freedom.
pub fn t_critical(p: f64, dof: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 1e3);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if t_two_sided_p(mid, dof) > p { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

/// Per-test significance that keeps the family-wise false-alarm rate at `alpha` over `m` tests.
pub fn sidak(alpha: f64, m: usize) -> f64 {
    1.0 - (1.0 - alpha).powf(1.0 / m as f64)
}

/// Mean and variance of the mean of each element over independent batches (Welford).
#[derive(Clone, Debug)]
pub struct BatchStats {
    pub batches: usize,
    mean: Vec<f64>,
    m2: Vec<f64>,
}

impl BatchStats {
    pub fn new(len: usize) -> Self {
        Self { batches: 0, mean: vec![0.0; len], m2: vec![0.0; len] }
    }

    pub fn add(&mut self, values: &[f32]) {
        assert_eq!(values.len(), self.mean.len());
        self.batches += 1;
        let n = self.batches as f64;
        for ((m, s), &v) in self.mean.iter_mut().zip(&mut self.m2).zip(values) {
            let d = v as f64 - *m;
            *m += d / n;
            *s += d * (v as f64 - *m);
        }
    }

    pub fn mean(&self) -> &[f64] {
        &self.mean
    }

    /// Variance of the mean over batches (sample variance / batches).
    pub fn var_of_mean(&self) -> Vec<f64> {
        let n = self.batches as f64;
        self.m2.iter().map(|s| s / (n - 1.0) / n).collect()
    }
}

/// Pearson chi-square goodness of fit of `observed` counts against `expected` counts, pooling
/// cells with expected count below 5 (Mitsuba's recipe). Returns (statistic, dof, p-value).
pub fn chi2_test(observed: &[f64], expected: &[f64]) -> (f64, usize, f64) {
    let mut cells: Vec<(f64, f64)> = observed.iter().copied().zip(expected.iter().copied()).collect();
    cells.sort_by(|a, b| a.1.partial_cmp(&b.1).unwrap());
    let (mut pooled_o, mut pooled_e) = (0.0, 0.0);
    let mut stat = 0.0;
    let mut n_cells = 0;
    for (o, e) in cells {
        if e == 0.0 {
            assert!(o == 0.0, "a sample fell into a cell of zero probability");
            continue;
        }
        if e < 5.0 {
            pooled_o += o;
            pooled_e += e;
            if pooled_e >= 5.0 {
                stat += (pooled_o - pooled_e) * (pooled_o - pooled_e) / pooled_e;
                n_cells += 1;
                pooled_o = 0.0;
                pooled_e = 0.0;
            }
            continue;
        }
        stat += (o - e) * (o - e) / e;
        n_cells += 1;
    }
    if pooled_e > 0.0 {
        stat += (pooled_o - pooled_e) * (pooled_o - pooled_e) / pooled_e;
        n_cells += 1;
    }
    let dof = n_cells - 1;
    (stat, dof, chi2_sf(stat, dof as f64))
}
