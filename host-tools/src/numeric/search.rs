//! One-dimensional minimization.

/// Where a golden-section search ended: the bracket [lo, hi] and its two
/// interior points (x, f(x)).
pub struct GoldenBracket {
    /// Lower end of the bracket.
    pub lo: f64,
    /// Upper end of the bracket.
    pub hi: f64,
    /// The interior points (x, f(x)), lower x first.
    pub points: [(f64, f64); 2],
}

/// Golden-section search for the minimum of `f` on [a, b] with `iters`
/// reductions after the first two evaluations; returns the final two
/// interior points (x, f(x)).
pub fn golden_section(f: &mut dyn FnMut(f64) -> f64, a: f64, b: f64, iters: usize) -> [(f64, f64); 2] {
    golden_bracket(f, a, b, iters).points
}

/// [`golden_section`] with the final bracket: each reduction keeps the
/// sub-bracket of the lower interior point, shrinking it by (√5 − 1)/2.
pub fn golden_bracket(f: &mut dyn FnMut(f64) -> f64, mut a: f64, mut b: f64, iters: usize) -> GoldenBracket {
    let gr = (5f64.sqrt() - 1.0) / 2.0;
    let mut x1 = b - gr * (b - a);
    let mut x2 = a + gr * (b - a);
    let mut f1 = f(x1);
    let mut f2 = f(x2);
    for _ in 0..iters {
        if f1 < f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - gr * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + gr * (b - a);
            f2 = f(x2);
        }
    }
    GoldenBracket { lo: a, hi: b, points: [(x1, f1), (x2, f2)] }
}
