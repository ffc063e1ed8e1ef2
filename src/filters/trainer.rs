//! One front for the three trainers, so that training code picks the synthesis by
//! [`FilterType`] and stays the same otherwise.

use super::asef::AsefTrainer;
use super::mosse::MosseTrainer;
use super::umace::UmaceTrainer;
use super::{Filter, FilterType};

/// A UMACE, ASEF or MOSSE trainer with its default settings.
#[derive(Debug)]
pub(crate) enum FilterTrainer {
    /// [`UmaceTrainer`].
    Umace(UmaceTrainer),
    /// [`AsefTrainer`].
    Asef(AsefTrainer),
    /// [`MosseTrainer`].
    Mosse(MosseTrainer),
}

impl FilterTrainer {
    /// A trainer of type `kind` for `size x size` patches.
    pub(crate) fn new(kind: FilterType, size: usize) -> Self {
        match kind {
            FilterType::Umace => Self::Umace(UmaceTrainer::new(size)),
            FilterType::Asef => Self::Asef(AsefTrainer::new(size)),
            FilterType::Mosse => Self::Mosse(MosseTrainer::new(size)),
        }
    }

    /// The type this trainer makes.
    #[cfg(test)]
    pub(crate) fn kind(&self) -> FilterType {
        match self {
            Self::Umace(_) => FilterType::Umace,
            Self::Asef(_) => FilterType::Asef,
            Self::Mosse(_) => FilterType::Mosse,
        }
    }

    /// Patches added so far.
    #[cfg(test)]
    pub(crate) fn count(&self) -> u32 {
        match self {
            Self::Umace(t) => t.count(),
            Self::Asef(t) => t.count(),
            Self::Mosse(t) => t.count(),
        }
    }

    /// Adds a patch whose feature lies `(dx, dy)` from the patch centre. UMACE assumes a centred
    /// feature and ignores the offset: give it centred patches only
    /// ([`FilterType::learns_localisation`]).
    ///
    /// # Panics
    /// If the patch is not `size x size` (a programming error).
    pub(crate) fn add(&mut self, patch: &[f32], dx: f64, dy: f64) {
        match self {
            Self::Umace(t) => t.add(patch),
            Self::Asef(t) => t.add(patch, dx, dy),
            Self::Mosse(t) => t.add(patch, dx, dy),
        }
    }

    /// The synthesised filter, `None` when no patch was added.
    pub(crate) fn finish(self) -> Option<Filter> {
        match self {
            Self::Umace(t) => t.finish(),
            Self::Asef(t) => t.finish(),
            Self::Mosse(t) => t.finish(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filters::test_support::blob_scene;

    #[test]
    fn each_type_trains_the_same_as_its_own_trainer() {
        let n = 32;
        let patches: Vec<_> = (0..3)
            .map(|i| (blob_scene(n, i as f64, 1.0, i), i as f64, 1.0))
            .collect();
        for kind in FilterType::ALL {
            let mut t = FilterTrainer::new(kind, n);
            assert_eq!(t.kind(), kind);
            for (p, dx, dy) in &patches {
                t.add(p, *dx, *dy);
            }
            assert_eq!(t.count(), 3);
            let via_front = t.finish().expect("trained");
            let direct = match kind {
                FilterType::Umace => {
                    let mut d = UmaceTrainer::new(n);
                    patches.iter().for_each(|(p, _, _)| d.add(p));
                    d.finish()
                }
                FilterType::Asef => {
                    let mut d = AsefTrainer::new(n);
                    patches.iter().for_each(|(p, x, y)| d.add(p, *x, *y));
                    d.finish()
                }
                FilterType::Mosse => {
                    let mut d = MosseTrainer::new(n);
                    patches.iter().for_each(|(p, x, y)| d.add(p, *x, *y));
                    d.finish()
                }
            };
            assert_eq!(Some(via_front), direct, "{kind}");
        }
        assert!(FilterTrainer::new(FilterType::Mosse, 8).finish().is_none());
    }
}
