//! How a set of values spreads: its median, 98th percentile and largest, the three numbers
//! the IK tables give of an answer's pose error (as cuRobo and PyRoki report theirs beside
//! their success rate).

/// The median, 98th percentile and maximum of some values (nearest rank: each is one of the
/// values; NaN for none).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Spread {
    pub median: f64,
    pub p98: f64,
    pub max: f64,
}

impl Spread {
    /// The spread of `values` (NaN sorts last, so a NaN shows as the maximum).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Self {
        let mut v: Vec<f64> = values.into_iter().collect();
        v.sort_by(f64::total_cmp);
        let rank = |q: f64| -> f64 {
            if v.is_empty() {
                return f64::NAN;
            }
            // Nearest rank: the smallest value with at least q of the values at or below it.
            let k = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
            v[k - 1]
        };
        Spread {
            median: rank(0.5),
            p98: rank(0.98),
            max: v.last().copied().unwrap_or(f64::NAN),
        }
    }

    /// `median/p98/max`, each with `digits` significant digits.
    pub fn short(&self, digits: usize) -> String {
        let g = |x: f64| format_significant(x, digits);
        format!("{}/{}/{}", g(self.median), g(self.p98), g(self.max))
    }
}

/// `x` with `digits` significant digits, in plain notation between 1e-3 and 1e6, in
/// scientific notation outside it (an error of 3.2e-8 mm reads as such, not 0.000).
pub fn format_significant(x: f64, digits: usize) -> String {
    let digits = digits.max(1);
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return "0".into();
    }
    let magnitude = x.abs().log10().floor() as i32;
    if (-3..6).contains(&magnitude) {
        let decimals = (digits as i32 - 1 - magnitude).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.*e}", digits - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let s = Spread::of((1..=100).map(f64::from));
        assert_eq!((s.median, s.p98, s.max), (50.0, 98.0, 100.0));
        let s = Spread::of([3.0, 1.0, 2.0]);
        assert_eq!((s.median, s.p98, s.max), (2.0, 3.0, 3.0));
        assert!(Spread::of([]).median.is_nan());
    }

    #[test]
    fn significant_digits() {
        assert_eq!(format_significant(0.000032, 2), "3.2e-5");
        assert_eq!(format_significant(0.968, 3), "0.968");
        assert_eq!(format_significant(4.7612, 3), "4.76");
        assert_eq!(format_significant(0.0, 3), "0");
    }
}
