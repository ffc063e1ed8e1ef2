//! The corrector the command line asks for: a [`Config`] from the face commands' flags, and the
//! models from the built-in ones or the files named.

use anyhow::{Context, Result};
use unshear::detect::{Cascade, DetectorParams, ProposalNet};
use unshear::filters::{EyeFilters, FilterType};
use unshear::locate::network::LandmarkNet;
use unshear::{Config, Detector, FaceSearch, Models, Unshear};

use crate::args::{LocatorArg, ModelArgs};
use crate::usage_error;

/// `base` (the stills' default, or video's) with the flags of `m` applied.
pub fn config_from(m: &ModelArgs, base: Config) -> Config {
    let defaults = DetectorParams::default();
    let min_face = m.min_face.unwrap_or(0);
    // Flags of the Viola-Jones search choose it; so do the filters, which cannot judge the
    // network detector's windows.
    let viola_jones_flags = m.quick
        || m.thorough
        || m.no_shear_search
        || m.shear_hypotheses.is_some()
        || m.roll_hypotheses.is_some()
        || m.fallback_cascade
        || m.search_every_view
        || m.locator == Some(LocatorArg::Filters);
    let detector = match m.detector {
        Some(d) => d.into(),
        None if viola_jones_flags => Detector::ViolaJones,
        None => base.detector,
    };
    let mut c = Config {
        detector,
        min_face: m.min_face.unwrap_or(base.min_face),
        search: if m.thorough && !m.no_shear_search {
            FaceSearch::Thorough
        } else {
            FaceSearch::Quick
        },
        min_confidence: m.min_confidence,
        max_shear: m.max_shear,
        refinements: m.refine,
        proposals: !m.no_proposals,
        search_every_view: m.search_every_view,
        shear_hypotheses: m.shear_hypotheses.clone(),
        roll_hypotheses: if m.no_roll_search {
            Some(Vec::new())
        } else {
            m.roll_hypotheses.clone()
        },
        fallback_cascade: m.fallback_cascade && !m.no_shear_search,
        filter_type: m.filter_type.map_or(base.filter_type, FilterType::from),
        cascade: DetectorParams {
            min_size: (min_face, min_face),
            min_neighbors: m.min_neighbors.unwrap_or(defaults.min_neighbors),
            scale_factor: m.scale_factor.unwrap_or(defaults.scale_factor),
            ..defaults
        },
        ..base
    };
    if m.no_shear_search {
        c.shear_hypotheses = Some(Vec::new());
        c.roll_hypotheses = Some(Vec::new());
    }
    if let Some(locator) = m.locator {
        c.locator = locator.into();
    }
    if let Some(model) = m.shear_model {
        c.shear_model = model.into();
    }
    if let Some(crops) = m.max_crops {
        c.network_budget.max_passes = usize::from(crops);
    }
    c
}

/// The corrector for `m` on top of `base`, and the thread pool sized by `--jobs`. A value out
/// of range is a usage error (exit 2).
pub fn load_models(m: &ModelArgs, base: Config) -> Result<Unshear> {
    if let Some(jobs) = m.jobs {
        // Only fails if a global pool exists already, which nothing here creates before.
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(usize::from(jobs))
            .build_global();
    }
    let config = config_from(m, base);
    if let Err(e) = config.validate() {
        usage_error(&e.to_string());
    }
    let cascade = match &m.cascade {
        Some(p) => {
            Cascade::from_file(p).with_context(|| format!("loading cascade {}", p.display()))?
        }
        None => Cascade::frontal_face_alt2(),
    };
    let filters = match &m.filters {
        Some(p) => {
            EyeFilters::from_file(p).with_context(|| format!("loading filters {}", p.display()))?
        }
        None => EyeFilters::builtin(config.filter_type)
            .with_context(|| format!("loading the built-in {} filters", config.filter_type))?,
    };
    let network = match &m.network {
        Some(p) => {
            let bytes =
                std::fs::read(p).with_context(|| format!("reading network {}", p.display()))?;
            LandmarkNet::from_bytes(&bytes)
                .with_context(|| format!("loading network {}", p.display()))?
        }
        None => LandmarkNet::embedded().context("loading the built-in landmark network")?,
    };
    let proposals =
        ProposalNet::embedded().context("loading the built-in face proposal classifier")?;
    let detector =
        ProposalNet::embedded_detector().context("loading the built-in face detector")?;
    let models = Models {
        cascade,
        filters,
        network,
        proposals,
        detector,
    };
    Ok(Unshear::with_models(config, models)?)
}
