use super::combine::{combined_shear, consensus, holds_eyes, most_confident_of_overlapping};
use super::face::BoxReading;
use super::network_search::{
    first_crop_min_face, measured_view_min_width, network_windows, network_windows_desheared,
    settle_unsure_faces, window_is_new, DoubtfulWindow, HIDING_MIN_CONFIDENCE, STRONG_WINDOW_LOGIT,
    WEAK_WINDOW_FIRST_CROP_MIN_FACE,
};
use super::proposals::{proposal_detection, proposal_eyes, proposal_is_new, proposal_shows};
use super::viola_jones_search::{
    overlapping_groups, strongest_of_overlapping, tries_of_group, View, THOROUGH_BOX_TRIES,
    THOROUGH_HALF_STEP_LADDER, TURNED_DESHEARED_MIN_ROLL, TURNED_DESHEARED_SHEARS,
};
use super::*;
use crate::config::MIN_NETWORK_FACE;
use crate::detect::boxes::{box_around_eyes, eyes_in_box, EYE_DISTANCE_PER_BOX_WIDTH};
use crate::geometry::{Point, Rect};
use crate::locate::filters::{NormalizedFace, FACE_WIDTH};

/// A box that gave no face.
fn nothing_at(face_box: Rect) -> FoundBox {
    FoundBox {
        face_box,
        report: None,
    }
}

/// A corrector with the built-in models.
fn built(config: Config) -> Unshear {
    Unshear::new(config).expect("built-in models")
}

fn face(k: Option<f64>, confidence: f64) -> FaceReport {
    let p = Point::new(0.0, 0.0);
    FaceReport {
        face_box: Rect::new(0.0, 0.0, 10.0, 10.0),
        right_eye: p,
        left_eye: p,
        right_nostril: p,
        left_nostril: p,
        mouth: None,
        k,
        k_measured: k.unwrap_or(0.9),
        refused: k.is_none().then_some(super::Refusal::LowConfidence),
        outvoted: false,
        k_nose: None,
        k_mouth: None,
        nose_tip: None,
        k_nose_tip: None,
        nose_tip_psr: 0.0,
        roll_degrees: 0.0,
        confidence,
        psr: [0.0; 5],
        locator: Locator::Filters,
        k_network: None,
        k_points: None,
        spread: None,
        face_score: None,
    }
}

#[test]
fn only_a_weak_window_is_given_up_at_a_first_crop_reading_under_0_1() {
    use crate::locate::network::UNLIKELY_FACE_SCORE;
    assert_eq!(WEAK_WINDOW_FIRST_CROP_MIN_FACE, UNLIKELY_FACE_SCORE);
    // Under the strong windows' logit (the detector's weak windows on clutter, and below 0):
    // under 0.1.
    for logit in [-3.0, 0.0, 0.5, 1.0, 1.499] {
        assert_eq!(first_crop_min_face(logit), WEAK_WINDOW_FIRST_CROP_MIN_FACE);
    }
    // From it, and for a face found before (the strongest logit): never.
    for logit in [STRONG_WINDOW_LOGIT, 8.0, f32::INFINITY] {
        assert_eq!(first_crop_min_face(logit), 0.0);
    }
    // Far below the face score a face needs, from any window.
    const { assert!(WEAK_WINDOW_FIRST_CROP_MIN_FACE < super::face::RETRY_MIN_FACE_SCORE) };
}

#[test]
fn the_thorough_search_is_lenient_only_with_the_network() {
    let u = built(Config::default());
    let t = u.thorough_detectors().expect("thorough by default");
    assert_eq!(t.as_is.params().min_neighbors, THOROUGH_MIN_NEIGHBORS);
    assert_eq!(t.views.params().min_neighbors, THOROUGH_MIN_NEIGHBORS);
    assert_eq!(t.as_is.params().stage_slack, THOROUGH_STAGE_SLACK);
    assert_eq!(t.views.params().stage_slack, THOROUGH_STAGE_SLACK);
    assert_eq!(t.as_is.params().min_size, (0, 0));
    let floor = THOROUGH_VIEW_MIN_FACE;
    assert_eq!(t.views.params().min_size, (floor, floor));
    assert_eq!(u.roll_hypotheses, THOROUGH_ROLL_HYPOTHESES.to_vec());
    assert_eq!(t.shear_hypotheses, THOROUGH_SHEAR_HYPOTHESES.to_vec());
    assert_eq!(
        u.hypothesis_groups(),
        vec![vec![0.15, -0.15], vec![0.3, -0.3], vec![0.45, -0.45]]
    );
    assert_eq!(u.shear_hypotheses, DEFAULT_SHEAR_HYPOTHESES.to_vec());
    assert_eq!(
        u.detector.params().min_neighbors,
        3,
        "the main detector unchanged"
    );
    assert_eq!(u.detector.params().stage_slack, 0);
    let u = built(Config {
        locator: Locator::Filters,
        ..Config::default()
    });
    assert!(
        u.thorough_detectors().is_none(),
        "the filters cannot judge boxes"
    );
    assert_eq!(
        u.hypothesis_groups(),
        vec![vec![0.3, -0.3], vec![0.5, -0.5]]
    );
    let u = built(Config::quick());
    assert!(u.thorough_detectors().is_none());
    assert_eq!(u.roll_hypotheses, DEFAULT_ROLL_HYPOTHESES.to_vec());
    assert_eq!(u.shear_hypotheses, DEFAULT_SHEAR_HYPOTHESES.to_vec());
}

#[test]
fn hypotheses_are_grouped_by_magnitude_nearest_first() {
    let quick = |shears: &[f64]| {
        built(Config {
            shear_hypotheses: Some(shears.to_vec()),
            ..Config::quick()
        })
    };
    assert_eq!(
        quick(&[0.5, 0.3, -0.5, -0.3, 0.1]).hypothesis_groups(),
        vec![vec![0.1], vec![0.3, -0.3], vec![0.5, -0.5]]
    );
    assert!(quick(&[]).hypothesis_groups().is_empty());
}

#[test]
fn turned_views_follow_the_de_sheared_ones_nearest_first() {
    let views = |rolls: &[f64]| {
        built(Config {
            shear_hypotheses: Some(vec![0.3, -0.3]),
            roll_hypotheses: Some(rolls.to_vec()),
            ..Config::quick()
        })
        .view_groups()
    };
    let r = |d: f64| d.to_radians();
    assert_eq!(
        views(&[30.0, -10.0, 10.0, 0.0]),
        vec![
            vec![(0.3, 0.0), (-0.3, 0.0)],
            vec![(0.0, r(-10.0)), (0.0, r(10.0))],
            vec![(0.0, r(30.0))],
        ]
    );
    assert_eq!(views(&[]), vec![vec![(0.3, 0.0), (-0.3, 0.0)]]);
}

#[test]
fn the_thorough_views_take_turns_on_the_two_scale_ladders() {
    let unshear = built(Config::default());
    let views = unshear.every_view(true);
    let groups = unshear.view_groups();
    assert_eq!(views.len(), groups.iter().map(Vec::len).sum::<usize>());
    let mut at = 0;
    for (i, group) in groups.iter().enumerate() {
        let de_sheared = group.iter().all(|&(_, roll)| roll == 0.0);
        let ladder = if de_sheared && i % 2 == 0 {
            THOROUGH_HALF_STEP_LADDER
        } else {
            0.0
        };
        for &(k, roll) in group {
            assert_eq!(
                views[at],
                View {
                    k,
                    roll,
                    scale_offset: ladder
                },
                "group {i}"
            );
            at += 1;
        }
    }
    // The views of +-0.15 and +-0.3 (the two nearest to k = 0.2) differ in ladder, and so
    // do +-0.3 and +-0.45; the turned views are on OpenCV's.
    assert_eq!(views[0].scale_offset, THOROUGH_HALF_STEP_LADDER);
    assert_eq!(views[2].scale_offset, 0.0);
    assert_eq!(views[4].scale_offset, THOROUGH_HALF_STEP_LADDER);
    assert!(views
        .iter()
        .filter(|v| v.roll != 0.0)
        .all(|v| v.scale_offset == 0.0));
    // Without the alternation (the filters' search of every view), OpenCV's ladder only.
    assert!(unshear
        .every_view(false)
        .iter()
        .all(|v| v.scale_offset == 0.0));
}

#[test]
fn strong_rolls_are_searched_again_de_sheared_by_the_measured_shear() {
    let unshear = built(Config::default());
    let strong: Vec<View> = unshear
        .every_view(true)
        .into_iter()
        .filter(|v| v.k == 0.0 && v.roll.to_degrees().abs() >= TURNED_DESHEARED_MIN_ROLL)
        .collect();
    assert_eq!(strong.len(), 4, "+-25 and +-45 degrees: {strong:?}");
    let found = |k: Option<f64>| {
        vec![FoundBox::face(
            Rect::new(0.0, 0.0, 10.0, 10.0),
            face(k, 0.8),
        )]
    };
    // An accepted face measured 0.37: the strong rolls at that shear, each on its ladder.
    let views = unshear.turned_desheared_views(&found(Some(0.37)));
    assert_eq!(views.len(), strong.len());
    for (v, s) in views.iter().zip(&strong) {
        assert_eq!(*v, View { k: 0.37, ..*s });
    }
    // A shear the cascade tolerates: nothing new to see.
    assert!(unshear
        .turned_desheared_views(&found(Some(0.05)))
        .is_empty());
    // No accepted face (refused, or none at all): one step each way.
    for nothing in [found(None), Vec::new()] {
        let views = unshear.turned_desheared_views(&nothing);
        assert_eq!(views.len(), TURNED_DESHEARED_SHEARS.len() * strong.len());
        for k in TURNED_DESHEARED_SHEARS {
            assert_eq!(views.iter().filter(|v| v.k == k).count(), strong.len());
        }
    }
}

#[test]
fn a_box_around_eyes_puts_them_where_the_turned_face_expects() {
    let eyes = Point::new(200.0, 150.0);
    for degrees in [0.0f64, 12.0, -25.0] {
        let roll = degrees.to_radians();
        let b = box_around_eyes(eyes, 120.0, 120.0, roll);
        assert_eq!((b.width, b.height), (120.0, 120.0));
        let gray = GrayImage::new(400, 300);
        let face = NormalizedFace::rotated(&gray, b, roll);
        let (at_x, at_y) = eyes_in_box();
        let expected = face.to_image(Point::new(at_x * FACE_WIDTH, at_y * FACE_WIDTH));
        assert!(expected.distance(eyes) < 1e-9, "{degrees}: {expected:?}");
    }
}

#[test]
fn boxes_scale_about_their_centre() {
    let b = Rect::new(10.0, 20.0, 100.0, 50.0);
    assert_eq!(b.scaled_about_center(1.0), b);
    let s = b.scaled_about_center(0.9);
    assert!((s.width - 90.0).abs() < 1e-12 && (s.height - 45.0).abs() < 1e-12);
    assert!((s.x - 15.0).abs() < 1e-12 && (s.y - 22.5).abs() < 1e-12);
}

/// A detection of a 100 px box at `x`, from the view de-sheared by `view_k`.
fn detection_at(x: f64, neighbors: u32, view_k: f64) -> Detection {
    Detection {
        face_box: Rect::new(x, 0.0, 100.0, 100.0),
        view_k,
        view_roll: 0.0,
        neighbors,
        near_miss: false,
    }
}

#[test]
fn overlapping_detections_keep_the_strongest_and_least_warped() {
    let d = detection_at;
    // Two overlapping boxes (IoU 0.82) and one apart.
    let kept = strongest_of_overlapping(vec![d(0.0, 3, 0.0), d(10.0, 7, 0.3), d(300.0, 1, 0.5)]);
    assert_eq!(kept.len(), 2);
    assert_eq!((kept[0].neighbors, kept[0].view_k), (7, 0.3));
    assert_eq!(kept[1].face_box.x, 300.0);
    // Equal neighbours: the view nearer the image as it is.
    let kept = strongest_of_overlapping(vec![d(0.0, 4, -0.5), d(5.0, 4, 0.3)]);
    assert_eq!((kept.len(), kept[0].view_k), (1, 0.3));
    // A detection before a near miss, whatever their neighbours.
    let near = Detection {
        near_miss: true,
        ..d(5.0, 9, 0.0)
    };
    let kept = strongest_of_overlapping(vec![near, d(0.0, 2, 0.5)]);
    assert_eq!(
        (kept.len(), kept[0].near_miss, kept[0].neighbors),
        (1, false, 2)
    );
}

#[test]
fn a_group_of_overlapping_boxes_is_tried_strongest_first_one_box_per_view() {
    let d = detection_at;
    let groups = overlapping_groups(vec![
        d(0.0, 2, 0.0),
        d(400.0, 1, 0.0),
        d(10.0, 9, 0.3),
        d(5.0, 5, 0.3),
        d(8.0, 4, -0.15),
        d(3.0, 3, 0.45),
        d(2.0, 1, -0.45),
    ]);
    assert_eq!(groups.len(), 2, "the face's boxes and the one apart");
    let strengths: Vec<u32> = groups[0].iter().map(|g| g.neighbors).collect();
    assert_eq!(strengths, vec![9, 5, 4, 3, 2, 1]);
    assert_eq!(groups[1].len(), 1);
    // The second box of the +0.3 view is skipped; the tries stop at THOROUGH_BOX_TRIES.
    let tries: Vec<(u32, f64)> = tries_of_group(groups[0].clone())
        .iter()
        .map(|t| (t.neighbors, t.view_k))
        .collect();
    assert_eq!(THOROUGH_BOX_TRIES, 3);
    assert_eq!(tries, vec![(9, 0.3), (4, -0.15), (3, 0.45)]);
    // Every group's first box is what `strongest_of_overlapping` keeps.
    let kept = strongest_of_overlapping(groups.concat());
    assert_eq!(kept, vec![groups[0][0], groups[1][0]]);
}

#[test]
fn overlapping_faces_keep_the_most_confident_estimate() {
    let at = |x: f64| Rect::new(x, 0.0, 100.0, 100.0);
    let kept = most_confident_of_overlapping(vec![
        nothing_at(at(0.0)),
        FoundBox::face(at(10.0), face(Some(0.1), 0.4)),
        FoundBox::face(at(5.0), face(None, 0.9)),
        nothing_at(at(400.0)),
    ]);
    assert_eq!(kept.len(), 2);
    assert_eq!(
        kept[0].face_box.x, 5.0,
        "the most confident of the three overlapping"
    );
    assert!(kept[1].report.is_none() && kept[1].face_box.x == 400.0);
}

#[test]
fn equally_confident_faces_keep_the_higher_face_score_whatever_came_first() {
    // A close face, refused, and a "face" on one of its eyes and cheek, refused too and found
    // first: the whole face's box holds the small one's eyes, so kept after it, the whole face
    // would be dropped as that face seen again.
    let refused = |x: f64, d: f64, score: f64| FaceReport {
        face_box: Rect::new(x - 1.3 * d, 100.0 - 0.9 * d, 2.6 * d, 2.6 * d),
        right_eye: Point::new(x - d / 2.0, 100.0),
        left_eye: Point::new(x + d / 2.0, 100.0),
        face_score: Some(score),
        refused: Some(Refusal::NotFaceLike),
        ..face(None, 0.0)
    };
    let (part, whole) = (refused(330.0, 38.0, 0.987), refused(300.0, 97.0, 0.999));
    assert!(holds_eyes(&whole.face_box, &part), "the case: a duplicate");
    for order in [[part, whole], [whole, part]] {
        let kept =
            most_confident_of_overlapping(order.map(|r| FoundBox::face(r.face_box, r)).to_vec());
        assert_eq!(
            kept[0].report.unwrap().face_score,
            Some(0.999),
            "the whole face first"
        );
        // The small one's box does not hold the whole face's eyes: a report of its own.
        assert_eq!(kept.len(), 2);
    }
}

#[test]
fn a_face_whose_box_holds_another_credible_face_is_refused() {
    // A head-and-shoulders box (accepted) whose box holds the eyes of a smaller face beside its
    // own located eyes; the smaller face refused for its pose, for low confidence, or accepted.
    let outer = FaceReport {
        face_box: Rect::new(0.0, 0.0, 300.0, 300.0),
        right_eye: Point::new(100.0, 120.0),
        left_eye: Point::new(200.0, 120.0),
        ..face(Some(0.25), 0.9)
    };
    let inner = |k: Option<f64>, refused: Option<Refusal>| FaceReport {
        face_box: Rect::new(200.0, 190.0, 80.0, 80.0),
        right_eye: Point::new(220.0, 220.0),
        left_eye: Point::new(250.0, 220.0),
        refused,
        ..face(k, if k.is_some() { 0.8 } else { 0.0 })
    };
    let run = |inner: FaceReport| {
        let kept = most_confident_of_overlapping(vec![
            FoundBox::face(outer.face_box, outer),
            FoundBox::face(inner.face_box, inner),
        ]);
        assert_eq!(kept.len(), 2, "two different faces, neither a duplicate");
        (kept[0].report.unwrap(), kept[1].report.unwrap())
    };
    let (o, i) = run(inner(None, Some(Refusal::UnreliablePose)));
    assert_eq!((o.k, o.refused), (None, Some(Refusal::NotFaceLike)));
    assert_eq!(o.k_measured, 0.25, "the measurement is kept");
    assert_eq!(i.refused, Some(Refusal::UnreliablePose));
    let (o, i) = run(inner(Some(0.1), None));
    assert_eq!(
        (o.k, i.k),
        (None, None),
        "both accepted: neither can be told right"
    );
    assert_eq!(i.refused, Some(Refusal::NotFaceLike));
    let (o, _) = run(inner(None, Some(Refusal::LowConfidence)));
    assert_eq!(
        (o.k, o.refused),
        (Some(0.25), None),
        "a weak claim refuses nothing"
    );
    // Side by side, neither box holding the other's eyes: both stand.
    let beside = FaceReport {
        face_box: Rect::new(400.0, 0.0, 300.0, 300.0),
        right_eye: Point::new(500.0, 120.0),
        left_eye: Point::new(600.0, 120.0),
        ..outer
    };
    let kept = most_confident_of_overlapping(vec![
        FoundBox::face(outer.face_box, outer),
        FoundBox::face(beside.face_box, beside),
    ]);
    assert!(kept.iter().all(|f| f.report.unwrap().k == Some(0.25)));
}

#[test]
fn a_proposal_counts_only_for_the_face_its_window_shows() {
    let window = proposal_detection(Point::new(200.0, 100.0), 40.0);
    let (eyes, distance) = proposal_eyes(&window);
    assert!(eyes.distance(Point::new(200.0, 100.0)) < 1e-9 && (distance - 40.0).abs() < 1e-9);
    let located = |dx: f64, dy: f64, d: f64| FaceReport {
        right_eye: Point::new(200.0 + dx - d / 2.0, 100.0 + dy),
        left_eye: Point::new(200.0 + dx + d / 2.0, 100.0 + dy),
        ..face(Some(0.1), 0.9)
    };
    assert!(proposal_shows(&window, &located(0.0, 0.0, 40.0)));
    // Up to half the window's eye distance away, and 1.5 times larger or smaller.
    assert!(proposal_shows(&window, &located(12.0, 12.0, 30.0)));
    assert!(!proposal_shows(&window, &located(0.0, 21.0, 40.0)));
    assert!(!proposal_shows(&window, &located(-21.0, 0.0, 40.0)));
    assert!(!proposal_shows(&window, &located(0.0, 0.0, 61.0)));
    assert!(!proposal_shows(&window, &located(0.0, 0.0, 26.0)));
}

#[test]
fn a_proposal_on_a_face_found_or_inside_it_is_not_searched() {
    // A face found with eyes 60 px apart at (300, 200), in its detector's box.
    let width = 60.0 / EYE_DISTANCE_PER_BOX_WIDTH;
    let found_box = box_around_eyes(Point::new(300.0, 200.0), width, width, 0.0);
    let found = vec![FoundBox::face(
        found_box,
        FaceReport {
            face_box: found_box,
            right_eye: Point::new(270.0, 200.0),
            left_eye: Point::new(330.0, 200.0),
            ..face(Some(0.1), 0.9)
        },
    )];
    // The same face, a little off: its box holds both eyes.
    assert!(!proposal_is_new(
        &proposal_detection(Point::new(305.0, 195.0), 55.0),
        &found
    ));
    // A small window on the face's nose, whose box holds neither eye.
    let nose = proposal_detection(Point::new(300.0, 240.0), 20.0);
    assert!(!nose.face_box.contains(Point::new(270.0, 200.0)));
    assert!(!proposal_is_new(&nose, &found));
    // A face beside it, two and a half eye distances away, and any face where none was
    // found (or only a box that gave no face).
    assert!(proposal_is_new(
        &proposal_detection(Point::new(450.0, 200.0), 60.0),
        &found
    ));
    assert!(proposal_is_new(&nose, &[]));
    assert!(proposal_is_new(&nose, &[nothing_at(found_box)]));
    // A window about a small "face" found on a large face's nose, holding neither of its
    // eyes: the large face is searched.
    let small_box = box_around_eyes(Point::new(300.0, 240.0), 50.0, 50.0, 0.0);
    let small = vec![FoundBox::face(
        small_box,
        FaceReport {
            face_box: small_box,
            right_eye: Point::new(290.0, 240.0),
            left_eye: Point::new(310.0, 240.0),
            ..face(Some(0.1), 0.9)
        },
    )];
    let large = proposal_detection(Point::new(300.0, 225.0), 60.0);
    assert!(small_box.contains(proposal_eyes(&large).0));
    assert!(large.face_box.contains(Point::new(290.0, 240.0)));
    assert!(proposal_is_new(&large, &small));
    // The same window at the small face's size is not.
    assert!(!proposal_is_new(
        &proposal_detection(Point::new(300.0, 240.0), 20.0),
        &small
    ));
}

/// A face found from a window with eyes 60 px apart at `(x, 200)`, as the network detector
/// keeps it (its window's box, the face), read with `confidence`.
fn found_at(x: f64, confidence: f64) -> FoundBox {
    let window = proposal_detection(Point::new(x, 200.0), 60.0).face_box;
    let report = FaceReport {
        face_box: window,
        right_eye: Point::new(x - 30.0, 200.0),
        left_eye: Point::new(x + 30.0, 200.0),
        ..face(Some(0.1), confidence)
    };
    FoundBox::face(window, report)
}

/// A face read with less than the default's confidence hides no window of about its size (it
/// may be a wrong reading beside the face that window reads right), but still hides the much
/// smaller windows on its parts; a face read with it hides both.
#[test]
fn an_unsure_face_hides_only_the_windows_on_its_parts() {
    let sure = [found_at(300.0, HIDING_MIN_CONFIDENCE)];
    let unsure = [found_at(300.0, 0.5 * HIDING_MIN_CONFIDENCE)];
    // Half an eye distance below: the window's box holds the face's eyes, and its eyes are in
    // the face's box.
    let below = proposal_detection(Point::new(300.0, 230.0), 60.0);
    let nose = proposal_detection(Point::new(300.0, 240.0), 20.0);
    for f in [&sure, &unsure] {
        assert!(!proposal_is_new(&below, f));
        assert!(!proposal_is_new(&nose, f));
        assert!(!window_is_new(&nose, f));
    }
    assert!(!window_is_new(&below, &sure));
    assert!(window_is_new(&below, &unsure));
}

/// Of two faces found where the first would have hidden the second's window, a sure second face
/// takes an unsure first one's place unless it located the same eyes; an unsure second face is
/// dropped; faces apart, and faces found before `first_new`, are left alone.
#[test]
fn a_sure_face_takes_an_unsure_ones_place_and_an_unsure_one_is_dropped() {
    let (low, high) = (0.5 * HIDING_MIN_CONFIDENCE, HIDING_MIN_CONFIDENCE);
    let settled = |mut found: Vec<FoundBox>, first_new: usize| {
        settle_unsure_faces(&mut found, first_new);
        found
            .iter()
            .map(|f| f.report.expect("a face").right_eye.x + 30.0)
            .collect::<Vec<_>>()
    };
    // A wrong reading first (unsure), then the face beside it read right (sure), then a face
    // of its own far away.
    let found = vec![
        found_at(300.0, low),
        found_at(320.0, high),
        found_at(600.0, low),
    ];
    assert_eq!(settled(found.clone(), 0), vec![320.0, 600.0]);
    // The other way round: the second, unsure reading is dropped.
    let found = vec![found_at(300.0, high), found_at(320.0, low)];
    assert_eq!(settled(found, 0), vec![300.0]);
    let found = vec![
        found_at(300.0, low),
        found_at(320.0, low),
        found_at(330.0, high),
    ];
    assert_eq!(settled(found, 0), vec![330.0]);
    // A sure reading of the same eyes as an unsure one is that face read again: the doubt
    // stands.
    let found = vec![found_at(300.0, low), found_at(303.0, high)];
    assert_eq!(settled(found, 0), vec![300.0]);
    // Faces before `first_new` are not settled against each other.
    let found = vec![found_at(300.0, low), found_at(320.0, low)];
    assert_eq!(settled(found, 2), vec![300.0, 320.0]);
}

#[test]
fn one_face_found_in_two_boxes_is_reported_once() {
    let located = |x: f64, confidence: f64| FaceReport {
        right_eye: Point::new(x, 50.0),
        left_eye: Point::new(x + 40.0, 50.0),
        ..face(Some(0.1), confidence)
    };
    let tight = Rect::new(80.0, 20.0, 105.0, 105.0);
    // A box three times as large (IoU 0.11) whose features led to the same eyes, 4 px off.
    let around_the_head = Rect::new(0.0, -60.0, 315.0, 315.0);
    assert!(tight.iou(&around_the_head) < 0.3);
    let kept = most_confident_of_overlapping(vec![
        FoundBox::face(around_the_head, located(104.0, 0.6)),
        FoundBox::face(tight, located(100.0, 0.9)),
        // Another face beside it, one eye distance and a half away: kept.
        FoundBox::face(Rect::new(150.0, 20.0, 105.0, 105.0), located(160.0, 0.5)),
    ]);
    assert_eq!(kept.len(), 2, "{kept:?}");
    assert_eq!(
        kept[0].face_box, tight,
        "the more confident of the two copies"
    );
    assert_eq!(kept[1].face_box.x, 150.0);
    // A more confident copy from a box beside the face, which does not hold the eyes it
    // located, gives way to the box that does.
    let beside = Rect::new(135.0, 20.0, 105.0, 105.0);
    let kept = most_confident_of_overlapping(vec![
        FoundBox::face(beside, located(102.0, 0.99)),
        FoundBox::face(tight, located(100.0, 0.9)),
    ]);
    assert_eq!(kept.len(), 1, "{kept:?}");
    assert_eq!(kept[0].face_box, tight);
    // A large box around the head whose walk stopped on other points (its located eyes far
    // from the face's, not the same face by `same_face`) but which holds the kept face's
    // eyes: the same face seen again, not reported.
    let stopped_elsewhere = FaceReport {
        right_eye: Point::new(90.0, 40.0),
        left_eye: Point::new(230.0, 0.0),
        ..face(Some(-0.5), 0.01)
    };
    let kept = most_confident_of_overlapping(vec![
        FoundBox::face(around_the_head, stopped_elsewhere),
        FoundBox::face(tight, located(100.0, 0.9)),
    ]);
    assert_eq!(kept.len(), 1, "{kept:?}");
    assert_eq!(kept[0].face_box, tight);
    // Without the tight face, it is reported (its own box holds its eyes).
    let alone =
        most_confident_of_overlapping(vec![FoundBox::face(around_the_head, stopped_elsewhere)]);
    assert_eq!(alone.len(), 1);
}

#[test]
fn combined_shear_is_the_weighted_median_of_the_consistent_majority() {
    assert_eq!(combined_shear(&[]), None);
    assert_eq!(combined_shear(&[face(None, 0.9)]), None);
    // Equal weights within each other's uncertainty (0.2 apart): the ordinary median.
    let even = [face(Some(0.1), 0.5), face(Some(0.3), 0.5)];
    assert!((combined_shear(&even).expect("k") - 0.2).abs() < 1e-12);
    // One confident face outweighs two doubtful ones that agree with each other, which are
    // outvoted; a refused face does not vote.
    let faces = [
        face(Some(0.40), 0.9),
        face(Some(0.05), 0.2),
        face(Some(0.06), 0.2),
        face(None, 1.0),
    ];
    let c = consensus(&faces);
    assert_eq!((c.k, c.outvoted.as_slice()), (Some(0.40), &[1, 2][..]));
    // Two agreeing faces outvote a third far off, whatever its value.
    let faces = [
        face(Some(0.2), 0.5),
        face(Some(0.22), 0.6),
        face(Some(-3.0), 0.55),
    ];
    let c = consensus(&faces);
    assert_eq!((c.k, c.outvoted.as_slice()), (Some(0.22), &[2][..]));
    assert!(!c.no_majority);
    // Two equally confident faces that cannot both be right: no shear, nobody outvoted.
    let split = [face(Some(0.0), 0.5), face(Some(0.3), 0.5)];
    let c = consensus(&split);
    assert_eq!((c.k, c.outvoted.len(), c.no_majority), (None, 0, true));
    // Two faces of about equal confidence far apart but within each other's uncertainty: not
    // the slightly heavier one's estimate, but a shear both can be right about.
    let u = super::combine::FACE_UNCERTAINTY;
    let apart = [face(Some(0.1656), 0.977), face(Some(0.0099), 0.966)];
    let k = combined_shear(&apart).expect("k");
    assert!((k - (0.0099 + u)).abs() < 1e-12, "{k}");
    // Just beyond twice the uncertainty is a disagreement; just within is not.
    assert!(combined_shear(&[face(Some(0.0), 0.5), face(Some(2.0 * u + 1e-3), 0.5)]).is_none());
    assert!(combined_shear(&[face(Some(0.0), 0.5), face(Some(2.0 * u - 1e-3), 0.5)]).is_some());
}

#[test]
fn no_face_means_no_k_and_correction_needs_one() {
    let unshear = built(Config::default());
    let img = DynamicImage::ImageLuma8(GrayImage::from_pixel(120, 90, image::Luma([128])));
    let report = unshear.estimate(&img);
    assert!(report.faces.is_empty() && report.k.is_none());
    assert!(Unshear::correct(&img, &report, &CorrectOptions::default()).is_err());
    let forced = CorrectOptions {
        k: Some(0.2),
        ..Default::default()
    };
    let out = Unshear::correct(&img, &report, &forced).expect("k given");
    assert_eq!((out.width(), out.height()), (120, 90));
    let bad = CorrectOptions {
        k: Some(f64::NAN),
        ..Default::default()
    };
    assert!(Unshear::correct(&img, &report, &bad).is_err());
}

#[test]
fn degenerate_boxes_give_no_estimate() {
    let unshear = built(Config::default());
    let gray = GrayImage::from_pixel(50, 50, image::Luma([0]));
    assert!(unshear
        .estimate_face(&gray, Rect::new(0.0, 0.0, 0.0, 10.0), FaceStart::default())
        .is_none());
    assert!(unshear
        .estimate_face(
            &gray,
            Rect::new(0.0, 0.0, f64::NAN, 10.0),
            FaceStart::default()
        )
        .is_none());
}

/// The default corrector, the bundled example (sheared by 0.3) in grey, its face, and that
/// face's eye midpoint and eye distance.
fn bundled_example_face() -> (Unshear, GrayImage, FaceReport, Point, f64) {
    let u = built(Config::default());
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/example/face-k0.30.png");
    let gray = Unshear::gray(&image::open(path).expect("bundled example"));
    let face = u.estimate_gray(&gray).faces[0];
    let eyes = face.right_eye.midpoint(face.left_eye);
    let distance = face.right_eye.distance(face.left_eye);
    (u, gray, face, eyes, distance)
}

/// A network detector window whose regressed eyes are off the face (here 0.7 eye distances to
/// the side, beyond [`proposal_shows`]'s 0.5) still finds it: the landmark network walks to the
/// face, and a second look from where it landed finds it there again.
#[test]
fn a_window_off_its_face_gets_a_second_look_from_where_the_network_landed() {
    let (u, gray, face, eyes, distance) = bundled_example_face();
    let window = Detection {
        view_k: 0.3,
        ..proposal_detection(Point::new(eyes.x + 0.7 * distance, eyes.y), distance)
    };
    let budget = u.config.network_budget;
    let first = u
        .estimate_face(
            &gray,
            window.face_box,
            FaceStart {
                k: 0.3,
                roll: 0.0,
                budget: Some(budget),
            },
        )
        .expect("the network finds the face from the window");
    assert!(
        !proposal_shows(&window, &first),
        "the window must be off: {first:?} {distance}"
    );
    let mut found = Vec::new();
    u.judge_windows(&gray, vec![(window, 5.0)], None, budget, &mut found);
    assert_eq!(found.len(), 1, "{found:?}");
    let (b, r) = (found[0].face_box, found[0].report.expect("an estimate"));
    // The face found again, in the second look's box around the eyes first located.
    assert!(r.right_eye.midpoint(r.left_eye).distance(eyes) < 0.1 * distance);
    let expected_width = distance / EYE_DISTANCE_PER_BOX_WIDTH;
    assert!((b.width / expected_width - 1.0).abs() < 0.15, "{b:?}");
    assert!(
        r.k.is_some_and(|k| (k - face.k_measured).abs() < 0.03),
        "{r:?}"
    );
}

/// A box read from starts turned each way ([`Unshear::read_box`] with `turned`) gives the face
/// with its estimate refused and no confidence; a box showing nothing is no face and not
/// doubtful either way.
#[test]
fn a_box_read_from_turned_starts_gives_the_face_refused() {
    let (u, gray, face, eyes, distance) = bundled_example_face();
    let start = FaceStart {
        k: 0.3,
        ..FaceStart::default()
    };
    let upright = u
        .read_box(&gray, face.face_box, start, false)
        .face()
        .expect("the face read as it is");
    assert!(upright.k.is_some(), "{upright:?}");
    let turned = u
        .read_box(&gray, face.face_box, start, true)
        .face()
        .expect("the face read from turned starts");
    assert_eq!(turned.k, None, "{turned:?}");
    assert_eq!(turned.refused, Some(Refusal::UnreliablePose));
    assert_eq!(turned.confidence, 0.0);
    // The same eyes (the network's eyes are within 0.10 eye distances for 96% of faces).
    assert!(turned.right_eye.midpoint(turned.left_eye).distance(eyes) < 0.1 * distance);
    let flat = GrayImage::from_pixel(gray.width(), gray.height(), image::Luma([128]));
    for turned in [false, true] {
        let read = u.read_box(&flat, face.face_box, start, turned);
        assert_eq!(read, BoxReading::NoFace, "turned: {turned}");
    }
}

/// The last resort for doubtful windows ([`Unshear::judge_doubtful_windows`]) adds a face no
/// other explains, refused, and nothing over a face already found.
#[test]
fn doubtful_windows_add_only_faces_not_found() {
    let (u, gray, _, eyes, distance) = bundled_example_face();
    let window = Detection {
        view_k: 0.3,
        ..proposal_detection(eyes, distance)
    };
    let doubtful = [DoubtfulWindow {
        window,
        logit: 5.0,
        start_k: None,
    }];
    let budget = u.config.network_budget;
    let mut found = Vec::new();
    u.judge_doubtful_windows(&gray, &doubtful, budget, &mut found);
    assert_eq!(found.len(), 1, "{found:?}");
    let r = found[0].report.expect("a face");
    assert_eq!((r.k, r.confidence), (None, 0.0), "{r:?}");
    let mut found = Vec::new();
    let left = u.judge_windows(&gray, vec![(window, 5.0)], None, budget, &mut found);
    assert!(left.is_empty(), "the face is read as it is: {left:?}");
    assert_eq!(found.len(), 1);
    u.judge_doubtful_windows(&gray, &doubtful, budget, &mut found);
    assert_eq!(found.len(), 1, "no second face over the first: {found:?}");
    assert!(found[0].report.is_some_and(|r| r.k.is_some()));
}

/// Looking at a frame's windows in parallel waves gives what looking at one after the other
/// gives: a window on the face a stronger window found is skipped (no face), the
/// others are looked at, in the windows' order.
#[test]
fn windows_looked_at_in_waves_are_judged_as_one_at_a_time() {
    let (u, gray, _, eyes, distance) = bundled_example_face();
    let at = |dx: f64, dy: f64| {
        let d = Detection {
            view_k: 0.3,
            ..proposal_detection(Point::new(eyes.x + dx, eyes.y + dy), distance)
        };
        (d, 5.0_f32)
    };
    let (w, h) = (f64::from(gray.width()), f64::from(gray.height()));
    let windows = vec![
        // Blank corners first, then the face, then the face again a little to the side.
        at(-eyes.x + 0.3 * distance, -eyes.y + 0.3 * distance),
        at(0.0, 0.0),
        at(w - eyes.x - 0.3 * distance, h - eyes.y - 0.3 * distance),
        at(0.15 * distance, 0.05 * distance),
    ];
    let budget = u.config.network_budget;
    let mut sequential = Vec::new();
    let mut found: Vec<FoundBox> = Vec::new();
    for (d, logit) in &windows {
        let look = if window_is_new(d, &found) {
            u.look_at_window(&gray, d, *logit, None, budget)
        } else {
            BoxReading::NoFace
        };
        if let Some(r) = look.face().filter(|r| proposal_shows(d, r)) {
            found.push(FoundBox::face(d.face_box, r));
        }
        sequential.push(look);
    }
    assert!(sequential[1].face().is_some(), "the face's window finds it");
    assert!(
        sequential[3].face().is_none(),
        "the second window on it is skipped"
    );
    let waves = u.look_at_windows(&gray, &windows, None, budget, &[]);
    assert_eq!(waves, sequential);
}

/// A second look finding a face that a weaker window's face hides takes that face's place
/// when it scores higher, and is dropped when it does not; a stronger window's face is not
/// looked past at all.
#[test]
fn a_second_look_displaces_only_weaker_windows_lower_scored_faces() {
    let (u, gray, _, eyes, distance) = bundled_example_face();
    let landing = Detection {
        view_k: 0.3,
        ..proposal_detection(eyes, distance)
    };
    // A "face" with eyes inside the landing's box, about as far apart: it hides the landing.
    let hiding = |face_score: f64| {
        let (r, l) = (
            Point::new(eyes.x - 0.4 * distance, eyes.y + 0.3 * distance),
            Point::new(eyes.x + 0.4 * distance, eyes.y + 0.3 * distance),
        );
        let report = FaceReport {
            face_box: box_around_eyes(r.midpoint(l), 2.0 * distance, 2.0 * distance, 0.0),
            right_eye: r,
            left_eye: l,
            face_score: Some(face_score),
            ..face(Some(0.1), 0.9)
        };
        FoundBox::face(report.face_box, report)
    };
    assert!(!window_is_new(&landing, &[hiding(0.9)]));
    let budget = u.config.network_budget;
    let judged = |hidden_by: FoundBox, its_logit: f32| {
        let mut found = vec![hidden_by];
        let second = [(landing, 5.0_f32)];
        u.take_second_looks(&gray, &second, None, budget, &mut found, vec![its_logit]);
        found
    };
    let weak = hiding(0.9);
    let found = judged(weak, 1.0);
    assert_eq!(found.len(), 1, "{found:?}");
    let r = found[0].report.expect("the face");
    assert!(
        r.right_eye.midpoint(r.left_eye).distance(eyes) < 0.1 * distance,
        "{r:?}"
    );
    assert!(r.face_score > Some(0.9));
    // Scored higher than the landing's face, or found by a stronger window: it stays.
    let strong = hiding(1.0);
    assert_eq!(judged(strong, 1.0), vec![strong]);
    assert_eq!(judged(weak, 9.0), vec![weak]);
}

/// The network detector's windows in a view de-sheared by the shear measured are moved back
/// onto the face in the input: the strongest window's eyes are where the face's are (within
/// a quarter of an eye distance, the detector's stated precision) and its shear is the view's
/// plus the little it regressed there (within 0.1 of the face's measured shear; the detector's
/// shear is off by a median 0.05). A shear of 0 gives the single pass's windows exactly.
#[test]
fn windows_of_a_de_sheared_view_land_on_the_face_in_the_input() {
    let (u, face_image, face, eyes, distance) = bundled_example_face();
    // The face near the top of a taller image: its eyes 190 rows above the middle row, where
    // the shear moves them by 57 px (a window not moved back would be an eye distance off).
    let mut gray = GrayImage::from_pixel(320, 600, image::Luma([128]));
    image::imageops::overlay(&mut gray, &face_image, 0, 0);
    let net = u
        .network_detector()
        .expect("the default uses the network detector");
    let windows = network_windows_desheared(net, &gray, 40.0, face.k_measured);
    let (strongest, logit) = windows.first().expect("a window on the face");
    let (at, width) = proposal_eyes(strongest);
    assert!(*logit > 0.0);
    assert!(at.distance(eyes) < 0.25 * distance, "{at:?} {eyes:?}");
    assert!((width / distance - 1.0).abs() < 0.2, "{width} {distance}");
    assert!(
        (strongest.view_k - face.k_measured).abs() < 0.1,
        "{} {}",
        strongest.view_k,
        face.k_measured
    );
    assert_eq!(
        network_windows_desheared(net, &gray, 40.0, 0.0),
        network_windows(net, &gray, 40.0)
    );
}

/// The pass over the de-sheared image looks for faces from half the smallest face found, on
/// the first pass's pyramid levels (never above that half, never below the first pass's
/// smallest face), and on an image wider than 1920 columns from no smaller a face than in the
/// image shrunk to 1920.
#[test]
fn the_de_sheared_pass_starts_on_the_first_pass_level_below_half_the_smallest_face() {
    let step = 2f64.sqrt();
    // Half of 200 is 100: levels 40, 56.6, 80, 113; 80 is the last at or below 100.
    assert!((measured_view_min_width(40.0, 200.0, 1920, step) - 80.0).abs() < 1e-9);
    // Exactly on a level.
    assert!((measured_view_min_width(40.0, 160.0, 640, step) - 80.0).abs() < 1e-9);
    // A smallest face under twice the first pass's: its own smallest.
    assert_eq!(measured_view_min_width(40.0, 60.0, 1920, step), 40.0);
    // Never below the network's smallest face.
    let floor = f64::from(MIN_NETWORK_FACE);
    assert_eq!(measured_view_min_width(1.0, 10.0, 640, step), floor);
    // 4000 columns: from 83 px at least (the level at 80), whatever the faces found.
    assert!((measured_view_min_width(40.0, 60.0, 4000, step) - 80.0).abs() < 1e-9);
    // A large face found there still sets the bound: half of 400, down to the level at 160.
    assert!((measured_view_min_width(40.0, 400.0, 4000, step) - 160.0).abs() < 1e-9);
}

#[test]
fn a_correction_changes_the_image_only_with_a_shear_to_apply() {
    let report = |k: Option<f64>, faces: Vec<FaceReport>| ImageReport {
        k,
        faces,
        faces_disagree: false,
        warnings: Vec::new(),
        width: 10,
        height: 10,
        readout: Readout::Rows,
        scene: None,
        k_source: None,
        scene_disagrees: false,
        row_shear: None,
    };
    let options = |region, k| CorrectOptions {
        region,
        k,
        ..CorrectOptions::default()
    };
    let refused = report(None, vec![face(None, 0.1)]);
    let accepted = report(Some(0.2), vec![face(Some(0.2), 0.9)]);
    let empty = report(None, Vec::new());
    for region in [Region::Image, Region::Face] {
        assert!(!options(region, None).changes(&refused), "{region:?}");
        assert!(!options(region, None).changes(&empty), "{region:?}");
        assert!(options(region, None).changes(&accepted), "{region:?}");
        assert!(options(region, Some(0.1)).changes(&refused), "{region:?}");
    }
    // A given shear corrects the whole image without a face, but face regions need one.
    assert!(options(Region::Image, Some(0.1)).changes(&empty));
    assert!(!options(Region::Face, Some(0.1)).changes(&empty));
}

#[test]
fn a_picture_read_by_columns_reports_its_vertical_shear() {
    let u = built(Config::default());
    // The row model's reading of an upright face sheared vertically by 0.3: a roll of t and a
    // shear of tan t, sin 2t = 0.6.
    let t = 0.6f64.asin() / 2.0;
    let mut sheared = face(Some(t.tan()), 0.9);
    sheared.roll_degrees = t.to_degrees();
    let mut refused = face(None, 0.1);
    refused.roll_degrees = t.to_degrees();
    let report = ImageReport {
        k: Some(t.tan()),
        faces: vec![sheared, refused],
        faces_disagree: false,
        warnings: vec![],
        width: 10,
        height: 10,
        readout: Readout::Rows,
        scene: None,
        k_source: None,
        scene_disagrees: false,
        row_shear: None,
    };
    let columns = u.read_by_columns(report);
    assert_eq!(columns.readout, Readout::Columns);
    let c = columns.faces[0].k.expect("accepted");
    assert!((c - 0.3).abs() < 1e-9, "{c}");
    assert!(columns.faces[0].roll_degrees.abs() < 1e-9);
    assert!((columns.k.expect("the image's k") - 0.3).abs() < 1e-9);
    // A refused face stays refused, for its own reason.
    assert_eq!(columns.faces[1].k, None);
    assert_eq!(columns.faces[1].refused, Some(Refusal::LowConfidence));
    assert_eq!(columns.warnings.len(), 1);
    // Converting twice changes nothing more.
    assert_eq!(u.read_by_columns(columns.clone()), columns);
    // Beyond --max-shear once converted: refused as implausible.
    let strong = 0.45f64;
    let ts = (2.0 * strong).asin() / 2.0;
    let mut far = face(Some(ts.tan()), 0.9);
    far.roll_degrees = ts.to_degrees();
    let strict = built(Config {
        max_shear: 0.4,
        ..Config::default()
    });
    let far = strict.read_by_columns(ImageReport {
        k: Some(ts.tan()),
        faces: vec![far],
        faces_disagree: false,
        warnings: vec![],
        width: 10,
        height: 10,
        readout: Readout::Rows,
        scene: None,
        k_source: None,
        scene_disagrees: false,
        row_shear: None,
    });
    assert_eq!(far.k, None);
    assert_eq!(far.faces[0].refused, Some(Refusal::ImplausibleShear));
    assert!((far.faces[0].k_measured - strong).abs() < 1e-9);
}

#[test]
fn a_correction_by_columns_straightens_a_vertically_sheared_line() {
    use image::{GrayImage, Luma};
    // A dark horizontal band at y = 40 of a 120 x 80 image, sheared vertically by 0.25 about
    // the middle column (through the transpose), then corrected as a column readout.
    let flat = GrayImage::from_fn(120, 80, |_, y| {
        Luma([if (38..42).contains(&y) { 20 } else { 220 }])
    });
    let t = |i: &DynamicImage| i.rotate90().fliph();
    let sheared = t(&crate::warp::apply_shear(
        &t(&DynamicImage::ImageLuma8(flat.clone())),
        crate::geometry::Shear::about_middle(0.25, 120),
        crate::warp::Interpolation::Linear,
        crate::warp::Canvas::Same,
    )
    .0);
    let report = ImageReport {
        k: Some(0.25),
        faces: vec![],
        faces_disagree: false,
        warnings: vec![],
        width: 120,
        height: 80,
        readout: Readout::Columns,
        scene: None,
        k_source: None,
        scene_disagrees: false,
        row_shear: None,
    };
    let fixed = Unshear::correct(&sheared, &report, &CorrectOptions::default())
        .expect("corrected")
        .to_luma8();
    let mean_error = |img: &GrayImage| {
        let rows = 10..70u32;
        let cols = 20..100u32;
        let n = (rows.len() * cols.len()) as f64;
        rows.flat_map(|y| cols.clone().map(move |x| (x, y)))
            .map(|(x, y)| {
                (f64::from(img.get_pixel(x, y)[0]) - f64::from(flat.get_pixel(x, y)[0])).abs()
            })
            .sum::<f64>()
            / n
    };
    // The band is back in place to within resampling blur (a few grey levels on average);
    // sheared, it was far off (a tenth of the pixels off by 200).
    assert!(mean_error(&fixed) < 3.0, "{}", mean_error(&fixed));
    assert!(mean_error(sheared.as_luma8().expect("grey")) > 15.0);
    // The rows model would have moved it sideways, not straightened it.
    let rows = ImageReport {
        readout: Readout::Rows,
        ..report
    };
    let wrong = Unshear::correct(&sheared, &rows, &CorrectOptions::default()).expect("corrected");
    assert!(mean_error(&wrong.to_luma8()) > 15.0);
}
