use super::*;
use crate::warp::{apply_shear, Canvas, Interpolation};
use crate::Shear;
use image::Rgb;

/// A still-camera-free base: no noise, no blur, rho 0.8.
fn params(width: u32, height: u32, motion: Profile) -> SimulationParams {
    SimulationParams {
        width,
        height,
        frames: 8,
        fps: 30.0,
        readout_fraction: 0.8,
        exposure: 0.0,
        motion,
        vertical: None,
        noise: 0.0,
        seed: 1,
    }
}

fn diff_stats(a: &RgbImage, b: &RgbImage, cols: std::ops::Range<u32>) -> (f64, u8) {
    let (mut sum, mut max, mut n) = (0.0, 0u8, 0usize);
    for y in 0..a.height() {
        for x in cols.clone() {
            for c in 0..3 {
                let d = a.get_pixel(x, y)[c].abs_diff(b.get_pixel(x, y)[c]);
                sum += f64::from(d);
                max = max.max(d);
                n += 1;
            }
        }
    }
    (sum / n as f64, max)
}

/// At a constant velocity the frame is `apply_shear` (k = rho V / H about H/2) of the still
/// view at the middle row's time. V = 30, rho = 0.8, frame 1: u(t_c) = 30 * 1.4 = 42 px, a
/// whole number, so the still view is an exact copy of the scene and both sides interpolate the
/// same samples once, linearly: they differ by the 8-bit rounding and `apply_shear`'s 1/256-px
/// phase steps, at most 2 levels. The opposite sign is far off, which pins the convention.
#[test]
fn constant_velocity_frame_is_apply_shear_of_the_still_view() {
    let scene = Scene::textured(500, 100, 7);
    let sim = Simulator::new(scene, params(200, 100, Profile::Constant { v: 30.0 })).unwrap();
    let (frame, truth) = sim.render(1).unwrap();
    let u = sim.offset(truth.time);
    assert!((u[0] - 42.0).abs() < 1e-9, "u(t_c) = {:?}", u);
    let mut still = RgbImage::new(200, 100);
    for (x, y, px) in still.enumerate_pixels_mut() {
        let s = sim.sample(
            f64::from(x) + sim.origin.x - u[0],
            f64::from(y) + sim.origin.y,
        );
        px.0 = s.map(|v| v.round() as u8);
    }
    let k = 0.8 * 30.0 / 100.0;
    assert!((truth.k - k).abs() < 1e-12);
    let shear = |k| {
        apply_shear(
            &DynamicImage::ImageRgb8(still.clone()),
            Shear::about_middle(k, 100),
            Interpolation::Linear,
            Canvas::Same,
        )
        .0
        .to_rgb8()
    };
    // |k (y - c)| <= 12 px: columns away from the fill at the sides.
    let (mean, max) = diff_stats(&frame, &shear(k), 16..184);
    assert!(max <= 2 && mean < 0.3, "mean {mean}, max {max}");
    let (wrong, _) = diff_stats(&frame, &shear(-k), 16..184);
    assert!(wrong > 5.0, "the opposite sign differs by only {wrong}");
}

/// Constant speed: k = rho V / H and row offsets on the line k (y - c) (second differences
/// zero to rounding).
#[test]
fn constant_speed_truth_is_a_line() {
    let sim = Simulator::new(
        Scene::textured(300, 120, 1),
        params(160, 120, Profile::Constant { v: -45.0 }),
    )
    .unwrap();
    let t = sim.truth(3);
    let k = 0.8 * -45.0 / 120.0;
    assert!((t.k - k).abs() < 1e-12, "k {}", t.k);
    assert_eq!(t.row_offsets.len(), 120);
    for (y, o) in t.row_offsets.iter().enumerate() {
        assert!((o - k * (y as f64 - 60.0)).abs() < 1e-6, "row {y}: {o}");
    }
    assert_eq!(t.row_offsets[60], 0.0);
    assert!(t.row_offsets_y.is_none());
    assert!((t.time - 3.4).abs() < 1e-12);
    assert_eq!(t.velocity, [-45.0, 0.0]);
}

/// Accelerate: u(t) = -V P / (2 pi) cos(2 pi t / P) + C analytically; the tabulated offsets
/// match it to 1e-4 px (the "well under 0.01 px" of the model), and at frame 0 (the velocity
/// crossing 0, the largest acceleration, 2 pi V / P) they bow away from their chord by about
/// a dt^2 / 8 = 0.785 * 225 * 0.64 / 8 = 14 px: a curve, not a line.
#[test]
fn accelerating_pan_gives_curved_row_offsets() {
    let v = 225.0;
    let sim = Simulator::new(
        Scene::textured(300, 720, 1),
        params(320, 720, Profile::Accelerate { v }),
    )
    .unwrap();
    let p = ACCELERATE_PERIOD_FRAMES;
    let u = |t: f64| -v * p / std::f64::consts::TAU * (std::f64::consts::TAU * t / p).cos();
    let t = sim.truth(0);
    let tc = 0.4;
    let mut bow = 0f64;
    for (y, o) in t.row_offsets.iter().enumerate() {
        let ty = 0.8 * y as f64 / 720.0;
        assert!((o - (u(ty) - u(tc))).abs() < 1e-4, "row {y}: {o}");
        let chord = t.row_offsets[0] + (t.row_offsets[719] - t.row_offsets[0]) * y as f64 / 719.0;
        bow = bow.max((o - chord).abs());
    }
    assert!(bow > 5.0 && bow < 20.0, "bow {bow}");
    let second: f64 = t
        .row_offsets
        .windows(3)
        .map(|w| w[0] - 2.0 * w[1] + w[2])
        .sum::<f64>();
    // They sum to the change of the slope across the frame, rho / H (v(bottom) - v(top)) =
    // 0.8 / 720 * 225 * sin(2 pi 0.8 / 8) = 0.147 (0 for a line).
    assert!(
        (second - 0.147).abs() < 0.005,
        "second differences sum to {second}"
    );
}

/// Pause: full speed at t = 0, still in the stop, reversed after it; shaky: |v| <= V and it
/// comes near V; both integrate to 1e-4 px of a fine midpoint sum.
#[test]
fn profiles_have_their_shapes_and_integrate_exactly() {
    let pause = Profile::Pause { v: 10.0 };
    assert_eq!(pause.velocity(0.0, 30.0), 10.0);
    assert_eq!(pause.velocity(40.0, 30.0), 0.0);
    assert_eq!(pause.velocity(59.0 + 5.0, 30.0), -10.0);
    let shaky = Profile::Shaky { v: 50.0, seed: 3 };
    let peak = (0..9000)
        .map(|i| shaky.velocity(i as f64 / 100.0, 30.0).abs())
        .fold(0.0, f64::max);
    assert!(peak <= 50.0 && peak > 25.0, "peak {peak}");
    for profile in [pause, shaky] {
        let track = Track::new(Some(profile), 30.0, -3.0, 40.0);
        let n = 400_000;
        let h = 37.3 / n as f64;
        let fine: f64 = (0..n)
            .map(|i| profile.velocity((i as f64 + 0.5) * h, 30.0) * h)
            .sum();
        assert!((track.at(37.3) - fine).abs() < 1e-4, "{profile:?}");
    }
}

/// A white vertical line on black, V = 50 px/frame, e = 0.2: smeared over V e = 10 px (11
/// columns with the bilinear taps), its light kept (255 in all, to the rounding of 11
/// pixels), centred where the line is at the row's time (the middle of the exposure).
#[test]
fn exposure_blurs_over_v_times_e() {
    let mut img = RgbImage::new(400, 40);
    for y in 0..40 {
        img.put_pixel(100, y, Rgb([255, 255, 255]));
    }
    let scene = Scene::new(img, Vec::new()).unwrap();
    let mut p = params(300, 40, Profile::Constant { v: 50.0 });
    p.exposure = 0.2;
    let sim = Simulator::new(scene, p).unwrap();
    let (frame, _) = sim.render(1).unwrap();
    let y = 20u32;
    let row: Vec<f64> = (0..300)
        .map(|x| f64::from(frame.get_pixel(x, y)[0]))
        .collect();
    let lit = row.iter().filter(|&&v| v > 2.0).count();
    let sum: f64 = row.iter().sum();
    let centre: f64 = row
        .iter()
        .enumerate()
        .map(|(x, v)| x as f64 * v)
        .sum::<f64>()
        / sum;
    assert!((9..=12).contains(&lit), "{lit} columns lit");
    assert!((sum - 255.0).abs() < 6.0, "light {sum}");
    let t = sim.params.row_time(1, 20.0);
    let expected = 100.0 - sim.origin.x + sim.offset(t)[0];
    assert!(
        (centre - expected).abs() < 0.3,
        "centre {centre}, expected {expected}"
    );
}

/// The panorama wraps: a pan of exactly its width (300 px over 3 frames) shows the same frame
/// again, and no column is ever the zero fill.
#[test]
fn the_panorama_wraps_around() {
    let scene = Scene::textured(300, 60, 5);
    let sim = Simulator::new(scene, params(200, 60, Profile::Constant { v: 100.0 })).unwrap();
    let (f0, _) = sim.render(0).unwrap();
    let (f3, _) = sim.render(3).unwrap();
    let (_, max) = diff_stats(&f0, &f3, 0..200);
    assert!(max <= 1, "frame 3 differs from frame 0 by {max}");
    for n in 0..4 {
        let (f, _) = sim.render(n).unwrap();
        for x in 0..200 {
            let col: u32 = (0..60).map(|y| u32::from(f.get_pixel(x, y)[1])).sum();
            assert!(col > 60 * 20, "frame {n} column {x} is dark");
        }
    }
}

/// Two white dots as the eyes of a scene face, a pan with vertical acceleration and a subject
/// walking with it: the truth's eye positions (row times solved) are where the rendered dots
/// are, to 0.5 px, and inside the frame by an eye distance.
#[test]
fn face_truth_is_where_the_eyes_are_rendered() {
    let mut img = RgbImage::new(400, 300);
    let (re, le) = (Point::new(150.0, 140.0), Point::new(190.0, 140.0));
    for e in [re, le] {
        for dy in -1..=1 {
            for dx in -1..=1 {
                img.put_pixel(
                    (e.x as i32 + dx) as u32,
                    (e.y as i32 + dy) as u32,
                    Rgb([255; 3]),
                );
            }
        }
    }
    let face = SceneFace {
        right_eye: re,
        left_eye: le,
    };
    let scene = Scene::new(img, vec![face]).unwrap();
    let mut p = params(240, 200, Profile::Constant { v: 7.0 });
    p.readout_fraction = 1.0;
    p.vertical = Some(Profile::Accelerate { v: 20.0 });
    let pan = Simulator::new(scene.clone(), p.clone()).unwrap();
    // The same dots on a walking subject (the background's copies are out of view).
    p.motion = Profile::Walk { v: 9.0 };
    let walk = Simulator::new(scene, p).unwrap();
    for (sim, n) in [(&pan, 0), (&pan, 1), (&pan, 2), (&walk, 0), (&walk, 2)] {
        let (frame, truth) = sim.render(n).unwrap();
        assert_eq!(truth.faces.len(), 1, "frame {n}");
        let f = &truth.faces[0];
        assert_eq!(f.subject, sim.sprite.is_some());
        assert_eq!(truth.row_offsets_y.is_some(), sim.sprite.is_none());
        for eye in [f.right_eye, f.left_eye] {
            assert!(eye[0] >= 40.0 && eye[0] <= 200.0 && eye[1] >= 40.0 && eye[1] <= 160.0);
            let (mut sx, mut sy, mut s) = (0.0, 0.0, 0.0);
            for y in (eye[1] as u32 - 8)..(eye[1] as u32 + 8) {
                for x in (eye[0] as u32 - 8)..(eye[0] as u32 + 8) {
                    let v = f64::from(frame.get_pixel(x, y)[0]);
                    sx += v * f64::from(x);
                    sy += v * f64::from(y);
                    s += v;
                }
            }
            let (cx, cy) = (sx / s, sy / s);
            assert!(
                (cx - eye[0]).abs() < 0.5 && (cy - eye[1]).abs() < 0.5,
                "frame {n}: dot at ({cx}, {cy}), truth {eye:?}"
            );
        }
        let t_eyes = sim
            .params
            .row_time(n, (f.right_eye[1] + f.left_eye[1]) / 2.0);
        let vx = sim.params.motion.peak();
        assert!((f.k - vx / 200.0).abs() < 1e-12);
        let vy = Profile::Accelerate { v: 20.0 }.velocity(t_eyes, 30.0);
        assert!((f.velocity[1] - vy).abs() < 1e-3);
    }
}

/// Walk: the camera is still, so rows the subject never reaches are the same in consecutive
/// frames, while its rows change; the truth gives the background k = 0 and the subject's
/// face k = rho V / H.
#[test]
fn walking_subject_moves_over_a_still_background() {
    let mut scene = Scene::textured(900, 200, 9);
    scene.faces.push(SceneFace {
        right_eye: Point::new(130.0, 90.0),
        left_eye: Point::new(150.0, 90.0),
    });
    let mut p = params(300, 200, Profile::Walk { v: 12.0 });
    p.exposure = 0.1;
    let sim = Simulator::new(scene, p).unwrap();
    let s = sim.sprite.clone().unwrap();
    let (f0, t0) = sim.render(0).unwrap();
    let (f1, t1) = sim.render(1).unwrap();
    let top = (s.start.y - s.half.1).floor() as u32;
    let bottom = (s.start.y + s.half.1).ceil() as u32;
    for y in (0..top).chain(bottom + 1..200) {
        for x in 0..300 {
            assert_eq!(f0.get_pixel(x, y), f1.get_pixel(x, y), "({x}, {y})");
        }
    }
    let changed = (top..=bottom)
        .flat_map(|y| (0..300).map(move |x| (x, y)))
        .filter(|&(x, y)| f0.get_pixel(x, y) != f1.get_pixel(x, y))
        .count();
    assert!(changed > 200, "only {changed} pixels changed");
    for t in [&t0, &t1] {
        assert_eq!(t.k, 0.0);
        assert!(t.row_offsets.iter().all(|&o| o == 0.0));
        let subject = t.subject.as_ref().unwrap();
        assert!((subject.k - 0.8 * 12.0 / 200.0).abs() < 1e-12);
        let face = t
            .faces
            .iter()
            .find(|f| f.subject)
            .expect("the subject's face");
        assert!((face.k - 0.8 * 12.0 / 200.0).abs() < 1e-12);
    }
    let (a, b) = (
        &t0.subject.as_ref().unwrap().center,
        &t1.subject.as_ref().unwrap().center,
    );
    assert!((b[0] - a[0] - 12.0).abs() < 1e-9);
}

/// A background face the walking subject passes in front of is left out of the truth while
/// it is covered (its eyes under the sprite's opaque part), and reported once uncovered, with
/// k = 0 (the camera is still).
#[test]
fn walking_subject_hides_the_faces_behind_it() {
    let mut scene = Scene::textured(900, 200, 9);
    scene.faces.push(SceneFace {
        right_eye: Point::new(130.0, 90.0),
        left_eye: Point::new(150.0, 90.0),
    });
    // The still view starts at x = 140 + 450 - 150 = 440: this face is at the frame's centre,
    // where the subject starts.
    scene.faces.push(SceneFace {
        right_eye: Point::new(580.0, 90.0),
        left_eye: Point::new(600.0, 90.0),
    });
    let sim = Simulator::new(scene, params(300, 200, Profile::Walk { v: 12.0 })).unwrap();
    assert!((sim.origin.x - 440.0).abs() < 1e-9);
    let background = |n| -> Vec<FaceTruth> {
        sim.truth(n)
            .faces
            .into_iter()
            .filter(|f| !f.subject)
            .collect()
    };
    assert!(background(0).is_empty());
    let later = background(5);
    assert_eq!(later.len(), 1);
    assert_eq!(later[0].face, 1);
    assert_eq!(later[0].k, 0.0);
    assert!((later[0].right_eye[0] - 140.0).abs() < 1e-9);
}

/// Bad values are refused with `InvalidArgument`, never a panic.
#[test]
fn validate_rejects_bad_params() {
    let good = params(64, 48, Profile::Constant { v: 3.0 });
    assert!(good.validate().is_ok());
    let bad: Vec<fn(&mut SimulationParams)> = vec![
        |p| p.readout_fraction = 0.0,
        |p| p.readout_fraction = 1.25,
        |p| p.readout_fraction = f64::NAN,
        |p| p.exposure = -0.1,
        |p| p.exposure = 1.5,
        |p| p.width = 0,
        |p| p.height = 0,
        |p| p.frames = 0,
        |p| p.width = MAX_SIDE + 1,
        |p| p.fps = 0.0,
        |p| p.noise = -1.0,
        |p| p.motion = Profile::Constant { v: f64::INFINITY },
        |p| p.motion = Profile::Shaky { v: 1e9, seed: 0 },
        |p| p.vertical = Some(Profile::Pause { v: f64::NAN }),
        |p| p.vertical = Some(Profile::Walk { v: 1.0 }),
    ];
    for (i, change) in bad.iter().enumerate() {
        let mut p = good.clone();
        change(&mut p);
        assert!(
            matches!(p.validate(), Err(Error::InvalidArgument(_))),
            "case {i}"
        );
        assert!(
            Simulator::new(Scene::textured(32, 32, 0), p).is_err(),
            "case {i}"
        );
    }
    let sim = Simulator::new(Scene::textured(32, 32, 0), good).unwrap();
    assert!(matches!(sim.render(8), Err(Error::InvalidArgument(_))));
    assert!(Scene::new(RgbImage::new(0, 5), Vec::new()).is_err());
    assert!(Scene::from_images(&[], 10).is_err());
}

/// Noise: the standard deviation asked for (within 5% over 30k samples), fresh every frame,
/// the same for the same seed.
#[test]
fn noise_has_its_sigma_and_changes_every_frame() {
    let scene = Scene::new(RgbImage::from_pixel(100, 100, Rgb([128; 3])), Vec::new()).unwrap();
    let mut p = params(100, 100, Profile::Constant { v: 0.0 });
    p.noise = 4.0;
    let sim = Simulator::new(scene, p).unwrap();
    let (a, _) = sim.render(0).unwrap();
    let (b, _) = sim.render(1).unwrap();
    let values: Vec<f64> = a.as_raw().iter().map(|&v| f64::from(v) - 128.0).collect();
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64).sqrt();
    // Rounding adds 1/12 to the variance.
    let expected = (16.0f64 + 1.0 / 12.0).sqrt();
    assert!(
        mean.abs() < 0.1 && (sd - expected).abs() < 0.05 * expected,
        "{mean} {sd}"
    );
    assert_ne!(a, b);
    assert_eq!(a, sim.render(0).unwrap().0);
}

/// Photos are scaled to the height and joined, their faces moved along.
#[test]
fn scenes_join_scaled_photos_and_move_their_faces() {
    let photo = |w, h, v| ScenePhoto {
        image: DynamicImage::ImageRgb8(RgbImage::from_pixel(w, h, Rgb([v; 3]))),
        faces: vec![SceneFace {
            right_eye: Point::new(9.5, 4.5),
            left_eye: Point::new(14.5, 4.5),
        }],
    };
    let scene = Scene::from_images(&[photo(40, 20, 10), photo(30, 10, 200)], 40).unwrap();
    assert_eq!(scene.image().dimensions(), (80 + 120, 40));
    assert_eq!(scene.image().get_pixel(10, 10)[0], 10);
    assert_eq!(scene.image().get_pixel(150, 10)[0], 200);
    let f = scene.faces();
    assert_eq!(f[0].right_eye, Point::new(19.5, 9.5));
    assert_eq!(f[1].right_eye, Point::new(80.0 + 39.5, 19.5));
}
