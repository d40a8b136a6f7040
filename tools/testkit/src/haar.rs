//! The 1D Haar basis of the near-field couplings (Sun & Ramamoorthi 2009,
//! eq. 8), written from its definition, and the coupling integral by the
//! midpoint rule: the independent side of the near-field tests.

/// Basis function `i` at `w`, written from the definition (not from the
/// pieces the couplings use).
pub fn basis(i: usize, w: f64) -> f64 {
    if !(0.0..1.0).contains(&w) {
        return 0.0;
    }
    if i == 0 {
        return 1.0;
    }
    let level = (i as f64).log2().floor() as i32;
    let t = (i - (1usize << level)) as f64;
    let x = 2f64.powi(level) * w - t;
    let amplitude = 2f64.powf(f64::from(level) / 2.0);
    if (0.0..0.5).contains(&x) {
        amplitude
    } else if (0.5..1.0).contains(&x) {
        -amplitude
    } else {
        0.0
    }
}

/// The largest magnitude of basis function `i`: 2^(level/2).
pub fn amplitude(i: usize) -> f64 {
    if i == 0 {
        1.0
    } else {
        2f64.powf((i as f64).log2().floor() / 2.0)
    }
}

/// Midpoint rule for eq. 8 over `[0, 1)` with `samples` points.
pub fn integrate(i: usize, k: usize, s: f64, o: f64, samples: usize) -> f64 {
    let h = 1.0 / samples as f64;
    (0..samples)
        .map(|m| {
            let w = (m as f64 + 0.5) * h;
            basis(i, s * w + o) * basis(k, w)
        })
        .sum::<f64>()
        * h
}
