//! Helpers shared by the unit tests of several modules.

/// Whether two runs of floats are the same bit for bit (and equally long): the check of every
/// change that claims to compute the same values faster.
pub(crate) fn same_bits(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[cfg(test)]
mod tests {
    use super::same_bits;

    #[test]
    fn only_identical_bits_are_the_same() {
        assert!(same_bits(&[1.0, -0.0, f32::NAN], &[1.0, -0.0, f32::NAN]));
        // Equal as numbers, not as bits; and a run one value short.
        assert!(!same_bits(&[0.0], &[-0.0]));
        assert!(!same_bits(&[1.0, 2.0], &[1.0]));
        assert!(!same_bits(&[1.0], &[1.0 + f32::EPSILON]));
    }
}
