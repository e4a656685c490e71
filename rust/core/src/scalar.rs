//! Smooth scalar functions used by the exponential and logarithm maps. They are evaluated in
//! `f64` with series near the removable singularities, so the `f32` results keep full precision
//! near the identity.

/// `sin(x)/x`, 1 at 0.
#[inline]
pub(crate) fn sinc(x: f32) -> f32 {
    let x = f64::from(x);
    if x.abs() < 1e-4 {
        (1.0 - x * x / 6.0) as f32
    } else {
        (x.sin() / x) as f32
    }
}

/// `x·cot(x)`, 1 at 0.
#[inline]
pub(crate) fn x_cot_x(x: f32) -> f32 {
    let x = f64::from(x);
    if x.abs() < 1e-4 {
        (1.0 - x * x / 3.0) as f32
    } else {
        (x * x.cos() / x.sin()) as f32
    }
}

/// `(cos x − sin(x)/x)/x²`, −1/3 at 0.
#[inline]
pub(crate) fn cos_minus_sinc_over_sq(x: f32) -> f32 {
    let x = f64::from(x);
    let x2 = x * x;
    if x.abs() < 0.1 {
        (-1.0 / 3.0 + x2 / 30.0 - x2 * x2 / 840.0) as f32
    } else {
        ((x.cos() - x.sin() / x) / x2) as f32
    }
}

/// `(1 − x·cot x)/sin²x`, 1/3 at 0.
#[inline]
pub(crate) fn one_minus_x_cot_x_over_sin_sq(x: f32) -> f32 {
    let x = f64::from(x);
    let x2 = x * x;
    if x.abs() < 0.05 {
        (1.0 / 3.0 + 2.0 * x2 / 15.0 + 2.0 * x2 * x2 / 63.0) as f32
    } else {
        let s = x.sin();
        ((1.0 - x * x.cos() / s) / (s * s)) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_agree_with_direct_formulas_at_the_switch_points() {
        let direct_c = |x: f64| (x.cos() - x.sin() / x) / (x * x);
        let direct_g = |x: f64| (1.0 - x * x.cos() / x.sin()) / (x.sin() * x.sin());
        for x in [0.0999f32, 0.1001] {
            assert!((cos_minus_sinc_over_sq(x) as f64 - direct_c(x as f64)).abs() < 1e-7);
        }
        for x in [0.0499f32, 0.0501] {
            assert!((one_minus_x_cot_x_over_sin_sq(x) as f64 - direct_g(x as f64)).abs() < 1e-6);
        }
        assert_eq!(sinc(0.0), 1.0);
        assert_eq!(x_cot_x(0.0), 1.0);
        assert!((cos_minus_sinc_over_sq(0.0) + 1.0 / 3.0).abs() < 1e-7);
        assert!((one_minus_x_cot_x_over_sin_sq(0.0) - 1.0 / 3.0).abs() < 1e-7);
    }
}
