//! Plain statistics of a sampled series that every layer reads: its mean, how two series
//! correlate, where one turns. Nothing here knows recordings or models.

/// Pearson correlation of two equally long series (0 when either is constant).
pub fn correlation(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
    }
    if sxx > 0.0 && syy > 0.0 {
        (sxy / (sxx * syy).sqrt()).clamp(-1.0, 1.0)
    } else {
        0.0
    }
}

/// Direction reversals of `x`, ignoring wiggles below 10 % of its span (noise).
pub fn reversals(x: &[f64]) -> usize {
    reversal_positions(x).len()
}

/// Where [`reversals`] finds each reversal (the sample that confirms it).
pub fn reversal_positions(x: &[f64]) -> Vec<usize> {
    let (lo, hi) = x.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let band = 0.1 * (hi - lo);
    let (mut found, mut dir, mut extreme) = (Vec::new(), 0.0, x.first().copied().unwrap_or(0.0));
    for (k, &v) in x.iter().enumerate() {
        let d = v - extreme;
        if dir == 0.0 {
            if d.abs() > band {
                dir = d.signum();
                extreme = v;
            }
        } else if d * dir > 0.0 {
            extreme = v;
        } else if -d * dir > band {
            found.push(k);
            dir = -dir;
            extreme = v;
        }
    }
    found
}

/// The mean of a series (0 for an empty one).
pub fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    s / n.max(1) as f64
}
