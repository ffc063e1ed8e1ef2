//! Small robust statistics shared by the pipeline, video and the evaluation.

/// Median of the finite values (mean of the middle two for an even count); `None` when there
/// are none.
pub fn median(mut values: Vec<f64>) -> Option<f64> {
    values.retain(|v| v.is_finite());
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    Some(if n % 2 == 1 {
        values[n / 2]
    } else {
        (values[n / 2 - 1] + values[n / 2]) / 2.0
    })
}

/// The weighted median of `(value, weight)` pairs: the value where half of the total weight
/// lies on either side (midway to the next value when exactly half lies below). Pairs with a
/// non-finite value or weight are ignored; `None` when none is left.
pub(crate) fn weighted_median(pairs: impl IntoIterator<Item = (f64, f64)>) -> Option<f64> {
    let mut weighted: Vec<(f64, f64)> = pairs
        .into_iter()
        .filter(|(v, w)| v.is_finite() && w.is_finite())
        .collect();
    if weighted.is_empty() {
        return None;
    }
    weighted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = weighted.iter().map(|(_, w)| w).sum();
    let mut below = 0.0;
    for (i, &(v, w)) in weighted.iter().enumerate() {
        below += w;
        if below > total / 2.0 + 1e-12 {
            return Some(v);
        }
        if (below - total / 2.0).abs() <= 1e-12 {
            return Some(weighted.get(i + 1).map_or(v, |n| (v + n.0) / 2.0));
        }
    }
    weighted.last().map(|(v, _)| *v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_even_and_empty() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(vec![f64::NAN, 5.0]), Some(5.0));
        assert_eq!(median(vec![]), None);
    }

    #[test]
    fn weighted_median_follows_the_weight() {
        assert_eq!(weighted_median([(0.1, 1.0), (0.5, 3.0)]), Some(0.5));
        assert_eq!(weighted_median([(0.1, 1.0), (0.5, 1.0)]), Some(0.3));
        assert_eq!(weighted_median([(0.2, 1.0), (f64::NAN, 9.0)]), Some(0.2));
        assert_eq!(weighted_median([]), None);
    }
}
