//! End-to-end tests on real faces (tests/fixtures/faces, see SOURCE.md) with known synthetic
//! shear: the whole pipeline, detection included, as a user runs it.

use std::path::{Path, PathBuf};

use image::DynamicImage;
use unshear::warp::{apply_shear, Canvas, Interpolation};
use unshear::{Config, FaceSearch, Locator, Shear, Unshear};

/// The built-in models with each locator: the landmark network (the default) and the paper's
/// correlation filters; every contract below holds for both.
fn correctors() -> [(Locator, Unshear); 2] {
    [Locator::Network, Locator::Filters].map(|locator| {
        let unshear = built(Config {
            locator,
            ..Config::default()
        });
        assert_eq!(unshear.locator(), locator);
        (locator, unshear)
    })
}

/// A corrector with the built-in models.
fn built(config: Config) -> Unshear {
    Unshear::new(config).expect("built-in models")
}

fn fixtures() -> Vec<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/faces");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("fixture folder")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "jpeg"))
        .collect();
    v.sort();
    assert_eq!(v.len(), 3, "three fixture faces");
    v
}

fn load(p: &Path) -> DynamicImage {
    unshear::imageio::read_image(p, unshear::imageio::DEFAULT_MAX_PIXELS).expect("fixture decodes")
}

fn sheared(img: &DynamicImage, k: f64) -> DynamicImage {
    apply_shear(
        img,
        Shear::about_middle(k, img.height()),
        Interpolation::Linear,
        Canvas::Expand,
    )
    .0
}

/// The requirement: within 0.05 of the true k on each fixture for each k.
#[test]
fn estimate_within_0_05_of_the_true_shear() {
    for (locator, unshear) in correctors() {
        for path in fixtures() {
            let img = load(&path);
            for k in [-0.40, -0.20, 0.0, 0.20, 0.40] {
                let report = unshear.estimate(&sheared(&img, k));
                assert_eq!(
                    report.faces.len(),
                    1,
                    "{locator:?} {}: k {k}: one face",
                    path.display()
                );
                let est = report.k.expect("an estimate");
                assert!(
                    (est - k).abs() <= 0.05,
                    "{locator:?} {}: true {k}, estimated {est:.4}",
                    path.display()
                );
            }
        }
    }
}

/// Correcting with the estimate leaves only the estimate's own error: the corrected image is the
/// face sheared by `0.3 - estimate`, so re-estimating it must give the fixture's unsheared
/// estimate shifted by that residual, within 0.05 (the accuracy the test above asserts for every
/// fixture and shear; the corrected image has been resampled twice, which blurs it).
#[test]
fn correcting_removes_the_shear() {
    for (locator, unshear) in correctors() {
        let path = &fixtures()[0];
        let img = load(path);
        let base = unshear.estimate(&img).k.expect("estimate on the original");
        let distorted = sheared(&img, 0.3);
        let report = unshear.estimate(&distorted);
        let estimate = report.k.expect("estimate on the distorted image");
        let fixed = Unshear::correct(&distorted, &report, &Default::default()).expect("correct");
        assert_eq!(
            (fixed.width(), fixed.height()),
            (distorted.width(), distorted.height())
        );
        let residual = unshear
            .estimate(&fixed)
            .k
            .expect("estimate after correction");
        let expected = base + (0.3 - estimate);
        assert!(
            (residual - expected).abs() <= 0.05,
            "{locator:?}: residual {residual:.4}, expected {expected:.4} (original {base:.4}, estimate {estimate:.4})"
        );
    }
}

/// k is dimensionless: the estimate on a 1.5x enlarged image matches the original's within 0.03.
/// Equation 5 itself is exactly scale-invariant (unit test in `estimate.rs`); end to end, the
/// detector's box and the resampling differ slightly between the two sizes (measured: up to
/// 0.020 on these fixtures).
#[test]
fn estimate_is_unchanged_by_uniform_rescale() {
    for (locator, unshear) in correctors() {
        for path in fixtures() {
            let img = sheared(&load(&path), 0.2);
            let big = img.resize_exact(
                img.width() * 3 / 2,
                img.height() * 3 / 2,
                image::imageops::FilterType::Triangle,
            );
            let (a, b) = (
                unshear.estimate(&img).k.expect("k"),
                unshear.estimate(&big).k.expect("k"),
            );
            assert!(
                (a - b).abs() <= 0.03,
                "{locator:?} {}: {a:.4} vs {b:.4} after rescale",
                path.display()
            );
        }
    }
}

/// A mirror image shears the other way: its estimate is minus the original's, within 0.05 (the
/// accuracy the issue asks of an estimate). Equation 5 is exactly antisymmetric (unit test in
/// `estimate.rs`) and the filters are trained on mirrored copies too, but the detector's boxes
/// are not mirror-symmetric (measured: the two estimates differ by up to 0.032 here).
#[test]
fn mirror_image_gives_minus_k() {
    for (locator, unshear) in correctors() {
        for path in fixtures() {
            let img = sheared(&load(&path), 0.25);
            let a = unshear.estimate(&img).k.expect("k");
            let b = unshear.estimate(&img.fliph()).k.expect("k of mirror");
            assert!(
                (a + b).abs() <= 0.05,
                "{locator:?} {}: {a:.4} and mirrored {b:.4}",
                path.display()
            );
        }
    }
}

/// Points are reported in the input's own pixels: the eyes lie inside the face box, the
/// subject's right eye on the image's left, nostrils below the eyes, the mouth below them and
/// between the eyes. A clear lab photo is trusted: clear correlation peaks with the filters, a
/// face score near 1 and tight heatmaps with the network.
#[test]
fn points_are_in_image_pixels_with_the_subjects_sides() {
    let img = load(&fixtures()[1]);
    for (locator, unshear) in correctors() {
        let report = unshear.estimate(&img);
        let f = report.faces.first().expect("a face");
        assert_eq!(f.locator, locator);
        assert!(f.face_box.contains(f.right_eye) && f.face_box.contains(f.left_eye));
        assert!(f.right_eye.x < f.left_eye.x && f.right_nostril.x < f.left_nostril.x);
        assert!(f.right_nostril.y > f.right_eye.y + 10.0 && f.left_nostril.y > f.left_eye.y + 10.0);
        match locator {
            Locator::Filters => {
                assert!(f.psr[0] > 4.0 && f.psr[1] > 4.0, "eye PSRs {:?}", f.psr);
                assert!(f.face_score.is_none() && f.spread.is_none());
            }
            Locator::Network => {
                let score = f.face_score.expect("the network scores the face");
                assert!(score > 0.9, "face score {score}");
                // Heatmap spreads in eye distances: a sharp eye is a few crop pixels wide
                // (an eye distance is 29 crop pixels).
                let spread = f.spread.expect("the network's spreads");
                assert!(spread.iter().all(|&s| s > 0.0 && s < 0.25), "{spread:?}");
                let nose = f.nose_tip.expect("the network's nose point");
                assert!(nose.y > f.right_eye.y && nose.y < f.mouth.expect("mouth").y);
            }
        }
        assert!(
            f.confidence > 0.5,
            "{locator:?}: confidence {}",
            f.confidence
        );
        let mouth = f.mouth.expect("the built-in models locate the mouth");
        assert!(mouth.y > f.right_nostril.y && mouth.y > f.left_nostril.y);
        assert!(f.right_eye.x < mouth.x && mouth.x < f.left_eye.x);
        assert!(
            f.roll_degrees.abs() < 5.0,
            "{locator:?}: a lab face is upright: {}",
            f.roll_degrees
        );
    }
}

/// Beyond the cascade's tolerance (|k| = 0.7 here) the paper's single detection pass loses these
/// faces; the de-sheared retries find them, and the estimate is still within 0.05 (measured: at
/// most 0.036 off over these five cases). 0.7 is beyond the default plausible bound (0.6,
/// `Config::max_shear`), which is raised here: this is about finding the faces.
#[test]
fn de_sheared_detection_finds_faces_the_single_pass_misses() {
    let cases = [
        ("subject01.normal.jpeg", 0.7),
        ("subject01.normal.jpeg", -0.7),
        ("subject03.normal.jpeg", 0.7),
        ("subject14.normal.jpeg", 0.7),
        ("subject14.normal.jpeg", -0.7),
    ];
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/faces");
    for (locator, _) in correctors() {
        let default = built(Config {
            locator,
            max_shear: 0.8,
            ..Config::thorough()
        });
        let single_pass = built(Config {
            locator,
            search: FaceSearch::Quick,
            shear_hypotheses: Some(Vec::new()),
            roll_hypotheses: Some(Vec::new()),
            ..Config::thorough()
        });
        for (name, k) in cases {
            let img = sheared(&load(&dir.join(name)), k);
            assert!(
                single_pass.estimate(&img).faces.is_empty(),
                "{locator:?} {name} at {k}: the single pass should miss it"
            );
            let report = default.estimate(&img);
            let est = report.k.expect("found and estimated with the retries");
            assert!(
                (est - k).abs() <= 0.05,
                "{locator:?} {name}: true {k}, estimated {est}"
            );
        }
    }
}

/// Two people side by side, one still and one moving fast (its face sheared by 0.7, beyond the
/// cascade's tolerance): in the quick search the still face is found and trusted in the image
/// as it is, so the retries do not run and the moving face is missed; `search_every_view`
/// searches the de-sheared views all the same and finds it, each face with its own shear, as
/// the thorough search (the default) does with the network.
#[test]
fn searching_every_view_finds_a_second_face_sheared_beyond_the_cascade() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/faces");
    let still = Unshear::gray(&load(&dir.join("subject01.normal.jpeg")));
    let moving = Unshear::gray(&sheared(&load(&dir.join("subject14.normal.jpeg")), 0.7));
    let mut pair = image::GrayImage::new(still.width() + moving.width(), still.height());
    image::imageops::replace(&mut pair, &still, 0, 0);
    image::imageops::replace(&mut pair, &moving, i64::from(still.width()), 0);
    for locator in [Locator::Network, Locator::Filters] {
        let with = |search, search_every_view| {
            built(Config {
                locator,
                search,
                search_every_view,
                ..Config::thorough()
            })
        };
        let found = with(FaceSearch::Quick, false).estimate_gray(&pair);
        assert_eq!(
            found.faces.len(),
            1,
            "{locator:?}: only the still face in the quick search"
        );
        let unshear = with(FaceSearch::Quick, true);
        let mut faces = unshear.estimate_gray(&pair).faces;
        assert_eq!(faces.len(), 2, "{locator:?}: both faces");
        // The thorough search (the default) searches every view too, with the network.
        let thorough = with(FaceSearch::Thorough, false)
            .estimate_gray(&pair)
            .faces
            .len();
        let expected = if locator == Locator::Network { 2 } else { 1 };
        assert_eq!(thorough, expected, "{locator:?}: thorough");
        faces.sort_by(|a, b| a.face_box.x.total_cmp(&b.face_box.x));
        // The still face reads as it does alone (the second face does not disturb it), the
        // moving one within 0.05 of its shear. "As it does alone": to within how much the
        // network's estimate of one face depends on where its search starts (the box differs
        // in the pair). A still's face may stop at its first crop when that reads within
        // `landmarks::SHEAR_TOLERANCE` (0.03) of the crop's shear, and from six starts the
        // fixture face's estimates spread over 0.019 (`landmarks` test
        // `the_estimate_hardly_depends_on_the_start`, bound 0.025); here 0.004 against 0.016.
        // With the tolerance of 0.01 before, this bound was 0.01.
        let alone = unshear.estimate_gray(&still).faces[0].k_measured;
        let (a, b) = (faces[0].k_measured, faces[1].k_measured);
        let bound = if locator == Locator::Network {
            0.025
        } else {
            0.01
        };
        assert!(
            (a - alone).abs() <= bound,
            "{locator:?}: still face {a} alone {alone}"
        );
        assert!((b - 0.7).abs() <= 0.05, "{locator:?}: moving face {b}");
    }
}

/// The size that no test image reaches: a detector whose smallest box is this cannot fire.
const BLIND: (u32, u32) = (10_000, 10_000);

/// The fallback cascade is asked only when the main detector gives no accepted estimate: with a
/// main detector that cannot fire (its smallest box is larger than the image), the fallback
/// (`haarcascade_frontalface_default`) finds each fixture face, its box mapped onto alt2's
/// size, and the shear is estimated within 0.05 as with alt2; without a fallback nothing is
/// found.
#[test]
fn fallback_cascade_finds_what_the_main_detector_misses() {
    use unshear::detect::Cascade;
    use unshear::filters::FilterType;
    // The paper's filters and the quick search, with a main cascade that never fires.
    let blind = |fallback_cascade| {
        let mut models = unshear::Models::builtin(FilterType::DEFAULT).expect("built-in models");
        // One stage whose threshold is above what its one tree can give.
        let never_fires = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/never_fires_cascade.xml");
        models.cascade = Cascade::from_file(&never_fires).expect("a valid cascade");
        let config = Config {
            locator: Locator::Filters,
            fallback_cascade,
            ..Config::quick()
        };
        Unshear::with_models(config, models).expect("valid")
    };
    // The quick search, whose views are all on OpenCV's scale ladder as the fallback's are (the
    // thorough search scans some views half a scale step up, which moves its box sizes).
    let alt2 = built(Config::quick());
    let (without, with) = (blind(false), blind(true));
    for path in fixtures() {
        let img = sheared(&load(&path), 0.2);
        assert!(without.estimate(&img).faces.is_empty());
        let report = with.estimate(&img);
        assert_eq!(report.faces.len(), 1, "{}", path.display());
        let main = alt2.estimate(&img);
        let (b, a) = (report.faces[0].face_box, main.faces[0].face_box);
        // Same face, same size to within the spread of the two cascades' box ratio (quartiles
        // 0.94-1.0 around the 0.967 used).
        assert!(b.iou(&a) > 0.8, "{}: {b:?} vs alt2 {a:?}", path.display());
        assert!((b.width / a.width - 1.0).abs() < 0.08, "{b:?} vs {a:?}");
        let k = report.k.expect("an estimate");
        assert!((k - 0.2).abs() <= 0.05, "{}: {k}", path.display());
    }
}

/// The thorough search's face proposals find a face the cascade cannot see: with a cascade that
/// cannot fire (its smallest box is larger than the image), the proposal classifier's windows
/// alone lead the network to each fixture face, sheared by -0.4, 0 and +0.4, and the shear is
/// estimated within 0.05; without proposals nothing is found.
#[test]
fn face_proposals_find_what_the_cascade_misses() {
    let blind = |proposals| {
        built(Config {
            proposals,
            cascade: unshear::detect::DetectorParams {
                min_size: BLIND,
                ..Default::default()
            },
            ..Config::thorough()
        })
    };
    let (without, with) = (blind(false), blind(true));
    for path in fixtures() {
        for k in [-0.4, 0.0, 0.4] {
            let img = sheared(&load(&path), k);
            assert!(without.estimate(&img).faces.is_empty());
            let report = with.estimate(&img);
            assert_eq!(report.faces.len(), 1, "{} at {k}", path.display());
            let found = report.k.expect("an accepted estimate");
            assert!(
                (found - k).abs() <= 0.05,
                "{} at {k}: {found}",
                path.display()
            );
        }
    }
}

/// A head rolled by 22 degrees: the features are searched again in the face turned upright by
/// the roll measured, so the estimate stays near the upright face's and the roll is measured
/// within 3 degrees, for every fixture and both directions. The network stays within 0.05 in all
/// six cases; the filters in five, and within 0.10 in the sixth (their estimates carry more of
/// the face's own error: 58 of 75 Yale estimates within 0.05, docs/accuracy.md; one fixture
/// rolled by -22 degrees reads 0.08 from upright). Before this second search, 5 of these 6
/// cases were 0.06-0.19 off with the filters, so the test can fail.
#[test]
fn rolled_faces_are_measured_upright() {
    use unshear::warp::rotate::rotate_gray;
    for (locator, unshear) in correctors() {
        let mut beyond = Vec::new();
        for path in fixtures() {
            let gray = Unshear::gray(&load(&path));
            let base = unshear.estimate_gray(&gray).k.expect("upright estimate");
            for degrees in [-22.0f64, 22.0] {
                // Turning the image by `a` (clockwise for a > 0) tilts the head by the same angle;
                // the reported roll is positive when the subject's left eye (image right) is lower,
                // i.e. for a clockwise tilt.
                let (turned, _) = rotate_gray(&gray, degrees.to_radians()).expect("rotate");
                let report = unshear.estimate_gray(&turned);
                assert_eq!(
                    report.faces.len(),
                    1,
                    "{locator:?} {}: {degrees}",
                    path.display()
                );
                let face = &report.faces[0];
                let off = format!(
                    "{locator:?} {}: tilted {degrees}, k {:.3} against upright {base:.3}",
                    path.display(),
                    face.k_measured
                );
                assert!((face.k_measured - base).abs() <= 0.10, "{off}");
                if (face.k_measured - base).abs() > 0.05 {
                    beyond.push(off);
                }
                assert!(
                    (face.roll_degrees - degrees).abs() <= 3.0,
                    "{locator:?} {}: tilted {degrees}, roll {:.1}",
                    path.display(),
                    face.roll_degrees
                );
            }
        }
        let allowed = usize::from(locator == Locator::Filters);
        assert!(beyond.len() <= allowed, "more than 0.05 off: {beyond:?}");
    }
}

/// The landmark network reports no face rolled beyond `estimate::MAX_ROLL` (57 degrees), the
/// points' model's limit: a fixture turned by 90 degrees, boxed where its upright box went and
/// searched from that roll, gives no face, while the same turned by 30 degrees is measured
/// (roll within 3 degrees). Without the limit the network follows the sideways face to its
/// eyes and reports it (roll about 90), which is how patterns read sideways and copies of
/// faces found in another box came through on the development photos.
#[test]
fn faces_rolled_beyond_the_model_are_not_reported() {
    use unshear::warp::rotate::rotate_gray;
    let unshear = Unshear::new(unshear::Config::default()).expect("built-in models");
    for path in fixtures() {
        let gray = Unshear::gray(&load(&path));
        let upright = unshear.estimate_gray(&gray);
        let face_box = upright.faces[0].face_box;
        for degrees in [30.0f64, 90.0] {
            let (turned, rotation) = rotate_gray(&gray, degrees.to_radians()).expect("rotate");
            let centre = rotation.to_view(face_box.center());
            let turned_box = unshear::Rect::new(
                centre.x - face_box.width / 2.0,
                centre.y - face_box.height / 2.0,
                face_box.width,
                face_box.height,
            );
            let start = unshear::FaceStart {
                roll: degrees.to_radians(),
                ..Default::default()
            };
            let report = unshear.estimate_face(&turned, turned_box, start);
            if degrees < 57.0 {
                let face = report.expect("a face rolled 30 degrees is measured");
                assert!(
                    (face.roll_degrees - degrees).abs() <= 3.0,
                    "{}: roll {:.1}",
                    path.display(),
                    face.roll_degrees
                );
            } else {
                assert!(
                    report.is_none(),
                    "{}: a face rolled {degrees} degrees reported: {report:?}",
                    path.display()
                );
            }
        }
    }
}

/// A face boxed too small or too large is searched again at the scale of its eyes
/// (`RESCALE_EYE_RATIO`): with the detector's box shrunk or grown by 15% about its centre, the
/// estimate stays within 0.03 of the one from the box itself, and the report keeps the box it
/// was given (measured: at most 0.019 off). Without the second search, 2 of these 6 cases were
/// 0.030-0.055 off (`subject01` boxed 15% small read 0.090 against 0.035).
#[test]
fn a_face_boxed_at_the_wrong_scale_is_measured_at_its_eyes_scale() {
    for (locator, unshear) in correctors() {
        for path in fixtures() {
            let gray = Unshear::gray(&load(&path));
            let detected = unshear.estimate_gray(&gray);
            let face = &detected.faces[0];
            let base = face.k_measured;
            for factor in [0.85, 1.15] {
                let scaled = face.face_box.scaled_about_center(factor);
                let report = unshear
                    .estimate_face(&gray, scaled, unshear::FaceStart::default())
                    .expect("an estimate");
                assert_eq!(report.face_box, scaled, "{locator:?} {}", path.display());
                assert!(
                    (report.k_measured - base).abs() <= 0.03,
                    "{locator:?} {}: box x{factor}, k {:.3} against {base:.3}",
                    path.display(),
                    report.k_measured
                );
            }
        }
    }
}

/// The thorough search (the default) asks the cascade for boxes of a single raw hit, which fire
/// on textured wall; the network's face score and the size floor for such boxes must leave
/// only the real face. A Yale face sheared by 0.15 (same canvas) on a larger one: before the
/// size floor this frame gave a second face, a 21 px box on the wall that scored 0.95 as a
/// face. And frames of sharp and blurred noise give none.
#[test]
fn the_thorough_search_reports_no_false_faces() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/faces");
    let img = load(&dir.join("subject01.normal.jpeg"));
    let shear = Shear::about_middle(0.15, img.height());
    let face = Unshear::gray(&apply_shear(&img, shear, Interpolation::Linear, Canvas::Same).0);
    let (w, h) = (face.width() + 80, face.height() + 80);
    let mut wall = image::GrayImage::from_pixel(w, h, image::Luma([128]));
    image::imageops::replace(&mut wall, &face, 31, 50);
    let mut state = 0x2545_f491_u32;
    let noise = image::GrayImage::from_fn(640, 480, |_, _| {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        image::Luma([(state >> 24) as u8])
    });
    let blurred = image::imageops::blur(&noise, 3.0);
    for config in [Config::default(), Config::thorough()] {
        let unshear = built(config.clone());
        for (what, frame, faces) in [
            ("wall", &wall, 1),
            ("noise", &noise, 0),
            ("blurred noise", &blurred, 0),
        ] {
            let found = unshear.estimate_gray(frame).faces;
            assert_eq!(
                found.len(),
                faces,
                "{:?} {what}: {found:?}",
                config.detector
            );
        }
    }
}

/// The default detector finds faces at the sizes and rolls it promises: each fixture face
/// rolled by 30 degrees each way, and shrunk until its box is about 45 pixels wide (the default
/// smallest face is 40), is found once and measured within 0.06 of the upright, full-size
/// face's shear; rolled by 45 degrees it is found, and its estimate is either that close or
/// refused (`NETWORK_DETECTOR_MAX_ROLL`: two of these six were read as sheared by 0.16-0.22);
/// rolled by 30 and sheared by 0.3 it is refused (`ROLLED_HEAD`).
#[test]
fn the_network_detector_finds_small_and_rolled_faces() {
    use unshear::warp::rotate::rotate_gray;
    let unshear = built(Config::default());
    for path in fixtures() {
        let gray = Unshear::gray(&load(&path));
        let upright = unshear.estimate_gray(&gray);
        let base = upright.k.expect("upright estimate");
        for degrees in [-45.0f64, -30.0, 30.0, 45.0] {
            let (turned, _) = rotate_gray(&gray, degrees.to_radians()).expect("rotate");
            let report = unshear.estimate_gray(&turned);
            assert_eq!(report.faces.len(), 1, "{}: {degrees}", path.display());
            let close = |k: f64| (k - base).abs() <= 0.06;
            match report.k {
                Some(k) => assert!(
                    close(k),
                    "{}: rolled {degrees}, k {k:.3} against upright {base:.3}",
                    path.display()
                ),
                None => assert_eq!(degrees.abs(), 45.0, "{}: {degrees}", path.display()),
            }
        }
        // Rolled by 30 degrees and then sheared by 0.3: strong roll and strong shear together
        // are what a head rolled further is misread as, so the estimate is refused.
        let (turned, _) = rotate_gray(&gray, 30f64.to_radians()).expect("rotate");
        let turned = Unshear::gray(&sheared(&DynamicImage::ImageLuma8(turned), 0.3));
        let report = unshear.estimate_gray(&turned);
        assert_eq!(
            report.faces.len(),
            1,
            "{}: rolled and sheared",
            path.display()
        );
        assert_eq!(report.k, None, "{}: rolled and sheared", path.display());
        assert_eq!(
            report.faces[0].refused,
            Some(unshear::pipeline::Refusal::UnreliablePose)
        );
        // Shrunk so that the face box is about 45 px wide.
        let width = upright.faces[0].face_box.width;
        let scale = 45.0 / width;
        let small = image::imageops::resize(
            &gray,
            (f64::from(gray.width()) * scale).round() as u32,
            (f64::from(gray.height()) * scale).round() as u32,
            image::imageops::FilterType::Triangle,
        );
        let report = unshear.estimate_gray(&small);
        assert_eq!(report.faces.len(), 1, "{}: small", path.display());
        assert!(
            report.k.is_some_and(|k| (k - base).abs() <= 0.06),
            "{}: small, k {:?} against {base:.3}",
            path.display(),
            report.k
        );
    }
}

/// A pan changing speed during the readout shears two faces at different heights differently:
/// the estimate bends the rows' offsets through both faces' shears, and the correction
/// straightens each face (a single shear would leave them 0.1 off or more).
#[test]
fn faces_at_different_heights_sheared_differently_bend_the_correction() {
    use image::GenericImage;
    let paths = fixtures();
    let (a, b) = (load(&paths[0]).to_rgb8(), load(&paths[2]).to_rgb8());
    let (w, h) = (a.width(), a.height());
    // One face in the upper half on the left, the other in the lower half on the right.
    let mut frame = image::RgbImage::from_pixel(2 * w + 120, 2 * h, image::Rgb([96, 96, 96]));
    frame.copy_from(&a, 0, 0).expect("fits");
    frame.copy_from(&b, w + 120, h).expect("fits");
    let frame = DynamicImage::ImageRgb8(frame);
    let height = frame.height();
    // The shear grows from 0.10 at the top face's middle row to 0.40 at the bottom face's.
    let (top, bottom) = (f64::from(h) / 2.0, f64::from(h) * 1.5);
    let truth = unshear::RowShear::new((top, 0.10), (bottom, 0.40)).expect("a curve");
    let pivot = f64::from(height) / 2.0;
    let moved: Vec<f64> = truth.offsets(height, pivot).iter().map(|d| -d).collect();
    let (distorted, _) = unshear::warp::try_shift_rows_on(
        &frame,
        &moved,
        pivot,
        Interpolation::Cubic,
        Canvas::Expand,
    )
    .expect("a canvas");
    let unshear = built(Config::default());
    let report = unshear.estimate(&distorted);
    let accepted: Vec<_> = report.faces.iter().filter(|f| f.k.is_some()).collect();
    assert_eq!(accepted.len(), 2, "{report:?}");
    let rows = report
        .row_shear
        .unwrap_or_else(|| panic!("no bend: {report:?}"));
    for f in &accepted {
        let y = f.right_eye.midpoint(f.left_eye).y;
        assert!(
            (rows.k_at(y) - truth.k_at(y)).abs() < 0.05,
            "row {y}: {} vs {}",
            rows.k_at(y),
            truth.k_at(y)
        );
    }
    let k = report.k.expect("a shear");
    assert!((k - rows.k_at(pivot)).abs() < 1e-12);
    // Corrected with the bend, both faces read upright again.
    let corrected = Unshear::correct(&distorted, &report, &Default::default()).expect("corrected");
    let again = unshear.estimate(&corrected);
    let left: Vec<f64> = again.faces.iter().filter_map(|f| f.k).collect();
    assert_eq!(left.len(), 2, "{again:?}");
    assert!(left.iter().all(|k| k.abs() < 0.05), "{left:?}");
    assert!(again.row_shear.is_none());
}
