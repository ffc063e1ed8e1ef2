//! The corrector the command line asks for: a [`Config`] from the face commands' flags, and the
//! models from the built-in ones or the files named.

use anyhow::{Context, Result};
use unshear::config::{Options, Search};
use unshear::detect::{Cascade, ProposalNet};
use unshear::filters::{EyeFilters, FilterType};
use unshear::locate::network::LandmarkNet;
use unshear::{Config, Models, Unshear};

use crate::args::ModelArgs;
use crate::usage_error;

/// The user options ([`unshear::config::OPTIONS`]) the flags of `m` give: the search flags
/// (`--thorough`, `--quick`, `--no-shear-search`) as `search`, `--no-roll-search` as no roll
/// hypotheses, `--no-proposals` as `proposals` off.
pub fn options_from(m: &ModelArgs) -> Options {
    let mut o = Options::default();
    o.detector = m.detector.map(Into::into);
    o.locator = m.locator.map(Into::into);
    o.search = if m.no_shear_search {
        Some(Search::Single)
    } else if m.thorough {
        Some(Search::Thorough)
    } else if m.quick {
        Some(Search::Quick)
    } else {
        None
    };
    o.min_confidence = Some(m.min_confidence);
    o.max_shear = Some(m.max_shear);
    o.max_crops = m.max_crops.map(usize::from);
    o.refinements = Some(m.refinements);
    o.shear_model = m.shear_model.map(Into::into);
    o.filter_type = m.filter_type.map(FilterType::from);
    o.min_face = m.min_face;
    o.min_neighbors = m.min_neighbors;
    o.scale_factor = m.scale_factor;
    o.proposals = m.no_proposals.then_some(false);
    o.fallback_cascade = m.fallback_cascade.then_some(true);
    o.search_every_view = m.search_every_view.then_some(true);
    o.shear_hypotheses = m.shear_hypotheses.clone();
    o.roll_hypotheses = if m.no_roll_search {
        Some(Vec::new())
    } else {
        m.roll_hypotheses.clone()
    };
    o.ruler = m.ruler.map(Into::into);
    o
}

/// `base` (the stills' default, or video's) with the flags of `m` applied, by the library's
/// one resolution of the options ([`Options::to_config`], as Python's keywords are).
pub fn config_from(m: &ModelArgs, base: Config) -> unshear::Result<Config> {
    options_from(m).to_config(base)
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
    let config = match config_from(m, base) {
        Ok(config) => config,
        Err(e) => usage_error(&e.to_string()),
    };
    // The cascade's XML takes about as long to parse as the rest together: parsed alongside
    // them on a second thread (each the same on either; a failure of the cascade is still
    // reported first).
    let (cascade, others) = rayon::join(
        || -> Result<Cascade> {
            Ok(match &m.cascade {
                Some(p) => Cascade::from_file(p)
                    .with_context(|| format!("loading cascade {}", p.display()))?,
                None => Cascade::frontal_face_alt2(),
            })
        },
        || -> Result<_> {
            let filters = match &m.filters {
                Some(p) => EyeFilters::from_file(p)
                    .with_context(|| format!("loading filters {}", p.display()))?,
                None => EyeFilters::builtin(config.filter_type).with_context(|| {
                    format!("loading the built-in {} filters", config.filter_type)
                })?,
            };
            let network = match &m.network {
                Some(p) => {
                    let bytes = std::fs::read(p)
                        .with_context(|| format!("reading network {}", p.display()))?;
                    LandmarkNet::from_bytes(&bytes)
                        .with_context(|| format!("loading network {}", p.display()))?
                }
                None => LandmarkNet::embedded().context("loading the built-in landmark network")?,
            };
            let proposals =
                ProposalNet::embedded().context("loading the built-in face proposal classifier")?;
            let detector =
                ProposalNet::embedded_detector().context("loading the built-in face detector")?;
            Ok((filters, network, proposals, detector))
        },
    );
    let cascade = cascade?;
    let (filters, network, proposals, detector) = others?;
    let models = Models {
        cascade,
        filters,
        network,
        proposals,
        detector,
    };
    Ok(Unshear::with_models(config, models)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::args::{Cli, Command};
    use clap::{ArgAction, CommandFactory, Parser};
    use unshear::config::{options, OptionKind};

    /// Options the command line spells otherwise than `--name`, with the flags that set them.
    const SPELLED_OTHERWISE: &[(&str, &[&str])] = &[(
        "search",
        // Three switches read better than `--search NAME` and are what the docs teach.
        &["thorough", "quick", "no-shear-search"],
    )];

    /// Every library option has a flag of its kind on the face commands (a switch named
    /// `--no-NAME` for one on by default), so a new `Config` option cannot go without one.
    #[test]
    fn every_option_has_a_flag_of_its_kind() {
        let cli = Cli::command();
        for command in ["estimate", "correct", "video"] {
            let sub = cli.find_subcommand(command).expect("a face command");
            let arg = |long: &str| {
                sub.get_arguments()
                    .find(|a| a.get_long() == Some(long))
                    .unwrap_or_else(|| panic!("{command}: no --{long}"))
            };
            for o in options() {
                let long = o.name.replace('_', "-");
                if let Some((_, flags)) = SPELLED_OTHERWISE.iter().find(|(n, _)| *n == o.name) {
                    for f in *flags {
                        assert!(matches!(arg(f).get_action(), ArgAction::SetTrue));
                    }
                    continue;
                }
                match o.kind {
                    OptionKind::Flag => {
                        let long = if o.default == "true" {
                            format!("no-{long}")
                        } else {
                            long
                        };
                        assert!(
                            matches!(arg(&long).get_action(), ArgAction::SetTrue),
                            "--{long} is a switch"
                        );
                    }
                    OptionKind::Integer | OptionKind::Number => {
                        let a = arg(&long);
                        assert!(a.get_action().takes_values(), "--{long} takes a value");
                        assert!(a.get_value_delimiter().is_none(), "--{long}: one value");
                    }
                    OptionKind::Numbers => {
                        let a = arg(&long);
                        assert!(a.get_action().takes_values(), "--{long} takes values");
                        assert_eq!(a.get_value_delimiter(), Some(','), "--{long}");
                    }
                    OptionKind::Choice(names) => {
                        let values: Vec<String> = arg(&long)
                            .get_possible_values()
                            .iter()
                            .map(|v| v.get_name().to_string())
                            .collect();
                        assert_eq!(values, names, "--{long}'s values");
                    }
                }
            }
        }
    }

    fn model_args(flags: &[&str]) -> ModelArgs {
        let line = ["unshear", "estimate", "in.jpg"].iter().chain(flags);
        match Cli::try_parse_from(line)
            .expect("a valid command line")
            .command
        {
            Command::Estimate(e) => e.model,
            _ => unreachable!("estimate"),
        }
    }

    /// Every option given on the command line reaches the library's `Options`.
    #[test]
    fn every_flag_reaches_the_options() {
        let m = model_args(&[
            "--detector=viola-jones",
            "--locator=filters",
            "--quick",
            "--min-confidence=0.3",
            "--max-shear=0.3",
            "--max-crops=3",
            "--refinements=2",
            "--shear-model=equation5",
            "--filter-type=umace",
            "--min-face=50",
            "--min-neighbors=2",
            "--scale-factor=1.2",
            "--no-proposals",
            "--fallback-cascade",
            "--search-every-view",
            "--shear-hypotheses=0.1,-0.1",
            "--roll-hypotheses=10",
            "--ruler=scene",
        ]);
        let o = options_from(&m);
        assert!(!format!("{o:?}").contains("None"), "{o:?}");
        let c = config_from(&m, Config::default()).expect("valid");
        assert_eq!(c.max_shear, 0.3);
        assert_eq!(c.refinements, 2);
        assert_eq!(c.network_budget.max_passes, 3);
        assert_eq!(c.ruler, unshear::Ruler::Scene);
        // The former spelling still works.
        assert_eq!(model_args(&["--refine=4"]).refinements, 4);
    }

    /// The flags' defaults give the library's defaults for stills and video.
    #[test]
    fn no_flags_give_the_presets() {
        let m = model_args(&[]);
        for base in [Config::default(), Config::video()] {
            let c = config_from(&m, base.clone()).expect("valid");
            assert_eq!(c, Options::default().to_config(base).expect("valid"));
        }
        let single = config_from(&model_args(&["--no-shear-search"]), Config::default());
        assert_eq!(single.expect("valid").shear_hypotheses, Some(Vec::new()));
    }
}
