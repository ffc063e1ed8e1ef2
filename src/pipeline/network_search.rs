//! The network detector's search: its windows over the image (and over the image de-sheared
//! by the shear its faces measured), each judged by the landmark network, the faces they show
//! settled against the faces found before, and a last resort for windows read doubtfully.

use image::GrayImage;
use rayon::prelude::*;

use super::combine::{
    holds_eyes, measured_shear, most_confident_of_overlapping, smaller_eye_distance,
};
use super::face::{BoxReading, FaceStart, MIN_FACE_SCORE};
use super::proposals::{
    hides, proposal_detection, proposal_detection_in, proposal_eyes, proposal_is_new,
    proposal_shows, scored_proposal_detections,
};
use super::report::{FaceReport, FoundBox, Refusal};
use super::viola_jones_search::{
    desheared_view, Detection, MEASURED_VIEW_MIN_SHEAR, NEAR_MISS_MIN_FACE_SCORE,
};
use super::Unshear;
use crate::config::{Locator, DEFAULT_MIN_CONFIDENCE, MIN_NETWORK_FACE};
use crate::detect::boxes::EYE_DISTANCE_PER_BOX_WIDTH;
use crate::detect::ProposalNet;
use crate::geometry::Rect;
use crate::locate::network::Budget;

/// A network detector's window whose look was doubtful: the landmark network's face score
/// short of a face's but not far short ([`RETRY_MIN_FACE_SCORE`](super::face::RETRY_MIN_FACE_SCORE)).
#[derive(Debug, Clone, Copy)]
pub(crate) struct DoubtfulWindow {
    pub(super) window: Detection,
    pub(super) logit: f32,
    /// The shear the window was read from, when known better than its own.
    pub(super) start_k: Option<f64>,
}

/// The smallest face the network detector's pass over the image de-sheared by the measured
/// shear looks for, as a share of the smallest face found
/// ([`Unshear::judge_measured_view`]): the faces of one photo are mostly at like distances
/// from the camera, and a face under half the size of every other was searched for by the
/// first pass all the same.
pub(crate) const MEASURED_VIEW_MIN_FACE_RATIO: f64 = 0.5;

/// The widest image (columns) whose faces the pass over the image de-sheared by the measured
/// shear looks for from the first pass's smallest face: on a wider image it looks from the
/// face that small in the image shrunk to this width (from about 83 px on a 4000x3000 photo),
/// so that it costs at most about what the first pass costs on a 1920x1080 frame, where a
/// second pass over all of a large photo's scales would double its search.
pub(crate) const MEASURED_VIEW_FULL_COLUMNS: f64 = 1920.0;

/// The smallest face (box width) the pass over an image `width` columns wide, de-sheared by
/// the measured shear, looks for when the first pass looked from `min_width` (at least
/// [`MIN_NETWORK_FACE`]) on pyramid levels `step` apart and the smallest face found is
/// `smallest` wide: [`MEASURED_VIEW_MIN_FACE_RATIO`] times `smallest` (and at least the bound
/// of [`MEASURED_VIEW_FULL_COLUMNS`]), taken down to the first pass's level holding it, so
/// that both passes see faces at the same scales (a borderline face's window comes and goes
/// with them).
pub(crate) fn measured_view_min_width(min_width: f64, smallest: f64, width: u32, step: f64) -> f64 {
    let min_width = min_width.max(f64::from(MIN_NETWORK_FACE));
    let wide = (f64::from(width) / MEASURED_VIEW_FULL_COLUMNS).max(1.0);
    let wanted = (MEASURED_VIEW_MIN_FACE_RATIO * smallest).max(min_width * wide);
    let levels = (wanted / min_width).ln() / step.ln();
    // The tolerance keeps a face exactly on a level on it (the logarithms' rounding).
    min_width * step.powf((levels + 1e-9).floor().max(0.0))
}

/// The largest head roll (degrees) of a face found by the network detector whose estimate is
/// accepted: at 45 degrees, two of the six fixture cases
/// (`the_network_detector_finds_small_and_rolled_faces`) were read as rolled about 39 degrees and
/// sheared by 0.16-0.22, with high confidence; at 30 degrees none was.
pub(crate) const NETWORK_DETECTOR_MAX_ROLL: f64 = 35.0;

/// The head roll (degrees) beyond which a face found by the network detector keeps its
/// estimate only when that is a small shear ([`ROLLED_HEAD_MAX_SHEAR`]): a head rolled 40-50
/// degrees can be read as rolled about 33 and sheared, stably (a second reading from a crop
/// turned by the measured roll, or 12 degrees more, repeats it). On the development faces
/// turned by 30 and +-45 degrees and sheared by 0, +-0.40 (`eval shear --roll`), this refuses
/// 56 of 70 accepted estimates more than 0.15 off; unturned (all nine shears), 16 of 8071
/// accepted estimates, none of them more than 0.15 off (docs/accuracy.md).
pub(crate) const ROLLED_HEAD: f64 = 25.0;

/// The largest shear (absolute) a face rolled beyond [`ROLLED_HEAD`] may be measured with.
pub(crate) const ROLLED_HEAD_MAX_SHEAR: f64 = 0.1;

/// The confidence from which a face found hides the network detector's windows of about its
/// size on it ([`window_is_new`]): the default's threshold. A face read with less can be a
/// wrong reading beside a real face (seen: "eyes" on a child's cheek and eye, or half a face
/// below the real eyes, confidence 0) that hid the window reading that face right.
pub(crate) const HIDING_MIN_CONFIDENCE: f64 = DEFAULT_MIN_CONFIDENCE;

/// Whether `face` is sure enough to hide the windows of about its size on it
/// ([`HIDING_MIN_CONFIDENCE`]).
pub(crate) fn hides_windows(face: &FaceReport) -> bool {
    face.confidence >= HIDING_MIN_CONFIDENCE
}

/// [`proposal_is_new`] for the network detector's windows, where only a face sure enough
/// ([`hides_windows`]) hides a window of about its size; any face hides the windows on its parts
/// much smaller than itself. A window an unsure face does not hide is looked at, and its face
/// settled against that one by [`settle_unsure_faces`].
pub(crate) fn window_is_new(window: &Detection, found: &[FoundBox]) -> bool {
    found.iter().all(|f| {
        f.report.is_none_or(|r| {
            let (hidden, much_larger) = hides(window, &r);
            !(hidden && (much_larger || hides_windows(&r)))
        })
    })
}

/// How close (in eye distances, the smaller face's) each eye of two readings must be for them to
/// be one reading of the same eyes: the landmark network's eyes are within 0.10 eye distances of
/// the truth for 96% of the development faces.
pub(crate) const SAME_EYES_EYE_DISTANCES: f64 = 0.25;

/// Whether two readings located the same eyes ([`SAME_EYES_EYE_DISTANCES`]).
fn same_eyes(a: &FaceReport, b: &FaceReport) -> bool {
    let near = SAME_EYES_EYE_DISTANCES * smaller_eye_distance(a, b);
    a.right_eye.distance(b.right_eye) < near && a.left_eye.distance(b.left_eye) < near
}

/// Settles the faces of `found` from `first_new` on, each found from the window its box is
/// (see [`window_is_new`]), against the faces before it that would have hidden that window
/// ([`proposal_is_new`]): a face sure enough ([`hides_windows`]) takes the place of the unsure
/// ones among them, unless one of those located the same eyes ([`same_eyes`]: the same face
/// read again, whose first reading's doubt stands; seen on a small face at a photo's edge,
/// refused for its pose, then read from another window with confidence 0.8 and a shear 0.28
/// off); any other face is dropped (the first reading of a spot stands).
pub(crate) fn settle_unsure_faces(found: &mut Vec<FoundBox>, first_new: usize) {
    let mut i = first_new;
    while i < found.len() {
        let FoundBox {
            face_box: b,
            report: Some(r),
        } = found[i]
        else {
            i += 1;
            continue;
        };
        let window = proposal_detection_in(b);
        let hiding: Vec<usize> = (0..i)
            .filter(|&j| found[j].report.is_some_and(|h| hides(&window, &h).0))
            .collect();
        if hiding.is_empty() {
            i += 1;
        } else if hides_windows(&r)
            && !hiding
                .iter()
                .any(|&j| found[j].report.is_some_and(|h| same_eyes(&h, &r)))
        {
            let unsure: Vec<usize> = hiding
                .into_iter()
                .filter(|&j| found[j].report.is_some_and(|h| !hides_windows(&h)))
                .collect();
            for &j in unsure.iter().rev() {
                found.remove(j);
            }
            i = i + 1 - unsure.len();
        } else {
            found.remove(i);
        }
    }
}

/// The window logit from which the network detector's window needs only the landmark network's
/// usual face score ([`MIN_FACE_SCORE`]); weaker windows need [`NEAR_MISS_MIN_FACE_SCORE`], as
/// the cascade's near misses do. Chosen on the development eval (all nine shears): 1.5 finds 5
/// more faces than 2 (every shear at 99% or more) with the same false faces accepted, 1 finds
/// one more still with a sixth more unmatched ones; 4 and 8 found 0.3-0.6 points fewer.
pub(crate) const STRONG_WINDOW_LOGIT: f32 = 1.5;

/// Faces narrower than this (box width, pixels) need the strict face score whatever their
/// window's logit: most false faces are small. On the development photos with their faces
/// painted over (`eval shear --face-free --min-face 40`), photos with an accepted face fell from
/// 21 to 15 of 871 and unmatched detections at k = 0 from 63 to 31, with the same faces found
/// (their boxes are all wider than 100 px).
pub(crate) const SMALL_WINDOW_FACE_WIDTH: f64 = 80.0;

/// Whether the face the landmark network found from a window of the network detector with
/// `logit` is a face: both networks' words together (see [`STRONG_WINDOW_LOGIT`] and
/// [`SMALL_WINDOW_FACE_WIDTH`]).
pub(crate) fn window_is_face(logit: f32, face: &FaceReport) -> bool {
    let small = face.right_eye.distance(face.left_eye) / EYE_DISTANCE_PER_BOX_WIDTH
        < SMALL_WINDOW_FACE_WIDTH;
    let needed = if logit >= STRONG_WINDOW_LOGIT && !small {
        MIN_FACE_SCORE
    } else {
        NEAR_MISS_MIN_FACE_SCORE
    };
    face.face_score.is_some_and(|s| s >= needed)
}

/// The face score under which the first crop of a weak window (logit under
/// [`STRONG_WINDOW_LOGIT`], which needs [`NEAR_MISS_MIN_FACE_SCORE`] to count as a face) ends
/// its look: the 0.1 under which the walk gives up after two crops anyway
/// ([`UNLIKELY_FACE_SCORE`](crate::locate::network::UNLIKELY_FACE_SCORE)). On the first 300
/// development photos at k = 0 and +-0.40, windows of logit 0-1 gave 24 faces in 830 looks,
/// windows of logit 8 and more 286 in 286. Stronger windows are followed past a first crop
/// however low it reads: ending theirs under 0.01 lost a small face accepted in the bench's
/// eight-faces scene, read 0.88 from its window's later crops.
pub(crate) const WEAK_WINDOW_FIRST_CROP_MIN_FACE: f64 = 0.1;

/// The face score under which the first crop of the look at a window with `logit` ends that
/// look ([`crate::locate::network::locate_within`]): [`WEAK_WINDOW_FIRST_CROP_MIN_FACE`] for
/// a weak window (under [`STRONG_WINDOW_LOGIT`]), 0 (never) for the others. Most windows of a
/// cluttered frame are weak and nothing, and a second crop only confirmed it.
pub(crate) fn first_crop_min_face(logit: f32) -> f64 {
    if logit < STRONG_WINDOW_LOGIT {
        WEAK_WINDOW_FIRST_CROP_MIN_FACE
    } else {
        0.0
    }
}

/// The network detector's windows in `gray` for faces at least `min_width` pixels wide
/// (not below [`MIN_NETWORK_FACE`]), strongest first, each with its logit.
pub(crate) fn network_windows(
    net: &ProposalNet,
    gray: &GrayImage,
    min_width: f64,
) -> Vec<(Detection, f32)> {
    let min_width = min_width.max(f64::from(MIN_NETWORK_FACE));
    scored_proposal_detections(net, gray, min_width, &net.default_params())
}

/// [`network_windows`] in `gray` de-sheared by `k` about its middle row (on a canvas wide
/// enough to lose nothing), moved back to `gray`: each window's shear is `k` plus the shear it
/// regressed in the view. A face sheared by about `k` is upright in the view, where the
/// detector is surest of it. None when the view would be mostly padding or cannot be made
/// ([`desheared_view`]); `k = 0` is the image as it is.
pub(crate) fn network_windows_desheared(
    net: &ProposalNet,
    gray: &GrayImage,
    min_width: f64,
    k: f64,
) -> Vec<(Detection, f32)> {
    if k == 0.0 {
        return network_windows(net, gray, min_width);
    }
    let Some((view, back)) = desheared_view(gray, k, 0.0) else {
        return Vec::new();
    };
    network_windows(net, &view, min_width)
        .into_iter()
        .map(|(d, logit)| {
            let (eyes, eye_distance) = proposal_eyes(&d);
            let eyes = back.to_input(eyes);
            let moved = Detection {
                view_k: d.view_k + k,
                view_roll: d.view_roll,
                ..proposal_detection(eyes, eye_distance)
            };
            (moved, logit)
        })
        .collect()
}

impl Unshear {
    /// The network detector's search of `gray` (see [`Unshear::detect_and_estimate`]): its
    /// windows judged by the landmark network ([`Self::judge_windows`]), then those over the
    /// image de-sheared by the shear the faces found measured ([`Self::judge_measured_view`]),
    /// then the last resort for the windows read doubtfully
    /// ([`Self::judge_doubtful_windows`]); of overlapping faces the most confident.
    pub(crate) fn network_search(&self, net: &ProposalNet, gray: &GrayImage) -> Vec<FoundBox> {
        let mut all: Vec<FoundBox> = Vec::new();
        let min_width = f64::from(self.config.min_face);
        let windows = network_windows(net, gray, min_width);
        let budget = self.config.network_budget;
        let mut doubtful = self.judge_windows(gray, windows, None, budget, &mut all);
        doubtful.extend(self.judge_measured_view(net, gray, min_width, budget, &mut all));
        self.judge_doubtful_windows(gray, &doubtful, budget, &mut all);
        most_confident_of_overlapping(all)
    }

    /// Judges the network detector's `windows` in `gray`, strongest first, each against the
    /// faces in `found` so far (a window on a face already found is skipped, [`window_is_new`];
    /// one on a face found unsure is looked at, and the two settled by
    /// [`settle_unsure_faces`]): the landmark
    /// network, started from the window's shear (or `start_k`, a shear known better, such as a
    /// video's filtered one) and roll with `budget`, must find a face there
    /// ([`window_is_face`]) and where the window expects it ([`proposal_shows`]). A face found
    /// elsewhere than the window expects (the window's regressed eyes are off, most often on
    /// strongly sheared faces) gets a second look from where the network landed, and counts
    /// when that look lands there again ([`Self::take_second_looks`]). The faces found join
    /// `found`; the windows whose look was doubtful are returned, each with the shear it was
    /// read from, for [`Self::judge_doubtful_windows`].
    pub(crate) fn judge_windows(
        &self,
        gray: &GrayImage,
        windows: Vec<(Detection, f32)>,
        start_k: Option<f64>,
        budget: Budget,
        found: &mut Vec<FoundBox>,
    ) -> Vec<DoubtfulWindow> {
        let first_new = found.len();
        // The logit of the window that found each face of `found`; the faces found before
        // count as found by the strongest.
        let mut found_by = vec![f32::INFINITY; found.len()];
        let mut second_looks = Vec::new();
        let looks = self.look_at_windows(gray, &windows, start_k, budget, found);
        let mut doubtful = Vec::new();
        for ((d, logit), look) in windows.iter().zip(looks) {
            match look {
                BoxReading::Doubtful => doubtful.push(DoubtfulWindow {
                    window: *d,
                    logit: *logit,
                    start_k,
                }),
                BoxReading::NoFace => {}
                BoxReading::Face(r) if proposal_shows(d, &r) => {
                    found.push(FoundBox::face(d.face_box, r));
                    found_by.push(*logit);
                }
                BoxReading::Face(r) => {
                    let landed = Detection {
                        view_k: r.k_measured,
                        view_roll: r.roll_degrees.to_radians(),
                        ..proposal_detection(
                            r.right_eye.midpoint(r.left_eye),
                            r.right_eye.distance(r.left_eye),
                        )
                    };
                    second_looks.push((landed, *logit));
                }
            }
        }
        // After every window's own look, so that a second look landing on part of a face
        // cannot hide that face's own window.
        self.take_second_looks(gray, &second_looks, start_k, budget, found, found_by);
        settle_unsure_faces(found, first_new);
        doubtful
    }

    /// The last resort for `windows` whose look was doubtful ([`Self::judge_windows`]),
    /// strongest first, once every window has been judged: each that no face found hides, sure
    /// or not ([`proposal_is_new`]), is read again from turned starts ([`Unshear::read_box`]),
    /// and a face found so where the window expects it, hidden by none either and apart from
    /// them (neither box holding the other's eyes), joins `found`, its estimate refused and with
    /// no confidence. Being last, such a face hides no window that reads a face as it is.
    pub(crate) fn judge_doubtful_windows(
        &self,
        gray: &GrayImage,
        windows: &[DoubtfulWindow],
        budget: Budget,
        found: &mut Vec<FoundBox>,
    ) {
        let mut windows = windows.to_vec();
        windows.sort_by(|a, b| b.logit.total_cmp(&a.logit));
        for w in windows {
            if !proposal_is_new(&w.window, found) {
                continue;
            }
            let start = FaceStart {
                k: w.start_k.unwrap_or(w.window.view_k),
                roll: w.window.view_roll,
                budget: Some(budget),
            };
            let BoxReading::Face(r) = self.read_box(gray, w.window.face_box, start, true) else {
                continue;
            };
            let read = proposal_detection(
                r.right_eye.midpoint(r.left_eye),
                r.right_eye.distance(r.left_eye),
            );
            // Nor may its box hold a found face's eyes, or its eyes be in a found face's box:
            // a doubtful reading is no reason to nest two faces.
            let apart = found.iter().all(|found| {
                found.report.is_none_or(|f| {
                    !holds_eyes(&w.window.face_box, &f) && !holds_eyes(&found.face_box, &r)
                })
            });
            if window_is_face(w.logit, &r)
                && proposal_shows(&w.window, &r)
                && proposal_is_new(&read, found)
                && apart
            {
                found.push(FoundBox::face(w.window.face_box, r));
            }
        }
    }

    /// Adds to `found` the faces the network detector finds in `gray` de-sheared by the shear
    /// the faces of `found` measured, when that is at least [`MEASURED_VIEW_MIN_SHEAR`]:
    /// rolling-shutter skew is one per frame, so there the faces the detector missed sheared
    /// are upright, where it is surest of them. Its windows are judged as the first pass's
    /// ([`Self::judge_windows`]), the landmark network started from the measured shear. Faces
    /// are looked for from [`MEASURED_VIEW_MIN_FACE_RATIO`] times the smallest face found (and
    /// `min_width`) up, on the first pass's scales: the pass's cost falls with the square of
    /// its smallest face, so on a frame with one large face it costs little.
    pub(super) fn judge_measured_view(
        &self,
        net: &ProposalNet,
        gray: &GrayImage,
        min_width: f64,
        budget: Budget,
        found: &mut Vec<FoundBox>,
    ) -> Vec<DoubtfulWindow> {
        let Some(k) = measured_shear(found).filter(|k| k.abs() >= MEASURED_VIEW_MIN_SHEAR) else {
            return Vec::new();
        };
        let smallest = found
            .iter()
            .filter_map(|f| f.report.map(|r| r.right_eye.distance(r.left_eye)))
            .fold(f64::INFINITY, f64::min)
            / EYE_DISTANCE_PER_BOX_WIDTH;
        let step = net.default_params().scale_step;
        let min_width = measured_view_min_width(min_width, smallest, gray.width(), step);
        let windows = network_windows_desheared(net, gray, min_width, k);
        self.judge_windows(gray, windows, Some(k), budget, found)
    }

    /// The second looks of [`Self::judge_windows`], strongest first, among the faces `found`
    /// by windows with logits `found_by`. A second look is skipped when it is on a face found
    /// by a window at least as strong as its own. A face it finds that weaker windows' faces
    /// hide (see [`window_is_new`]) takes their place if it scores higher than each of them,
    /// and is dropped otherwise: a weak window's false face (seen on a dog's muzzle beside a
    /// strongly sheared child) must not hide the face a stronger window saw from a little off.
    pub(super) fn take_second_looks(
        &self,
        gray: &GrayImage,
        second_looks: &[(Detection, f32)],
        start_k: Option<f64>,
        budget: Budget,
        found: &mut Vec<FoundBox>,
        mut found_by: Vec<f32>,
    ) {
        // The faces a look from a window with `logit` defers to.
        let stronger = |found: &[FoundBox], found_by: &[f32], logit: f32| {
            let by_stronger = found.iter().zip(found_by).filter(|&(_, &by)| by >= logit);
            by_stronger.map(|(f, _)| *f).collect::<Vec<_>>()
        };
        let looks: Vec<Option<FaceReport>> = second_looks
            .par_iter()
            .map(|(d, logit)| {
                window_is_new(d, &stronger(found, &found_by, *logit))
                    .then(|| self.look_at_window(gray, d, *logit, start_k, budget).face())
                    .flatten()
            })
            .collect();
        for ((d, logit), look) in second_looks.iter().zip(looks) {
            let Some(r) = look.filter(|r| proposal_shows(d, r)) else {
                continue;
            };
            // Faces found since the looks were taken (other second looks) may hide it now.
            if !window_is_new(d, &stronger(found, &found_by, *logit)) {
                continue;
            }
            // Only weaker windows' faces are left that can hide it.
            let hiding: Vec<usize> = (0..found.len())
                .filter(|&i| !window_is_new(d, &found[i..=i]))
                .collect();
            let scores_higher = |i: &usize| {
                let theirs = found[*i].report.and_then(|h| h.face_score);
                matches!((r.face_score, theirs), (Some(s), Some(t)) if s > t)
            };
            if !hiding.iter().all(scores_higher) {
                continue;
            }
            for &i in hiding.iter().rev() {
                found.remove(i);
                found_by.remove(i);
            }
            found.push(FoundBox::face(d.face_box, r));
            found_by.push(*logit);
        }
    }

    /// [`Self::look_at_window`] for each of `windows` in order, no face for a window on a face
    /// in `found` ([`window_is_new`]) when its turn comes, exactly as looking at one window
    /// after the other and adding each face found to `found` before the next (as `commit`
    /// does). Looks are taken in waves on the thread pool: a wave holds the windows up to the
    /// next one not yet looked at whose box overlaps an earlier window's (that window's face,
    /// once found, may hide it), so a frame's separate windows (a busy scene can give ten) do
    /// not wait for each other on one core, and no look is spent on a window its stronger
    /// neighbour's face will hide. Each look depends only on its window, so the results are
    /// those of one window at a time.
    pub(super) fn look_at_windows(
        &self,
        gray: &GrayImage,
        windows: &[(Detection, f32)],
        start_k: Option<f64>,
        budget: Budget,
        found: &[FoundBox],
    ) -> Vec<BoxReading> {
        let mut found_now = found.to_vec();
        // Each window's look once taken (`Some`), and each window's outcome once decided.
        let mut taken: Vec<Option<BoxReading>> = vec![None; windows.len()];
        let mut looks: Vec<BoxReading> = Vec::with_capacity(windows.len());
        while looks.len() < windows.len() {
            let next = looks.len();
            // The wave: from `next` on, every window not looked at yet and still new that no
            // earlier window still to be decided (and still new) overlaps.
            let wave: Vec<usize> = (next..windows.len())
                .filter(|&j| {
                    let (d, _) = &windows[j];
                    let overlaps = |e: &Detection| e.face_box.intersection(&d.face_box).is_some();
                    taken[j].is_none()
                        && window_is_new(d, &found_now)
                        && (next..j).all(|i| {
                            let (e, _) = &windows[i];
                            !overlaps(e) || !window_is_new(e, &found_now)
                        })
                })
                .collect();
            let seen: Vec<(usize, BoxReading)> = wave
                .par_iter()
                .map(|&j| {
                    let (d, logit) = &windows[j];
                    (j, self.look_at_window(gray, d, *logit, start_k, budget))
                })
                .collect();
            for (j, look) in seen {
                taken[j] = Some(look);
            }
            // Decided in order as far as the looks taken reach (a window no longer new needs
            // none).
            while let Some((d, _)) = windows.get(looks.len()) {
                let look = if !window_is_new(d, &found_now) {
                    BoxReading::NoFace
                } else if let Some(look) = taken[looks.len()].take() {
                    look
                } else {
                    break;
                };
                if let Some(r) = look.face().filter(|r| proposal_shows(d, r)) {
                    found_now.push(FoundBox::face(d.face_box, r));
                }
                looks.push(look);
            }
        }
        looks
    }

    /// The face the landmark network finds from the network detector's window `d` (with
    /// `logit`), started from its shear (or `start_k`) and roll with `budget`, if the network
    /// finds a face there ([`window_is_face`]); strongly rolled ones refused
    /// ([`NETWORK_DETECTOR_MAX_ROLL`]), and rolled ones measured strongly sheared
    /// ([`ROLLED_HEAD`]); a window giving no face may have been read doubtfully
    /// ([`Unshear::read_box`]). The look ends at its first crop when that reads as hardly a
    /// face, more readily for a weak window ([`first_crop_min_face`]).
    pub(super) fn look_at_window(
        &self,
        gray: &GrayImage,
        d: &Detection,
        logit: f32,
        start_k: Option<f64>,
        budget: Budget,
    ) -> BoxReading {
        let start = FaceStart {
            k: start_k.unwrap_or(d.view_k),
            roll: d.view_roll,
            budget: Some(budget),
        };
        let doubt = first_crop_min_face(logit);
        let mut r = match self.read_doubted_box(gray, d.face_box, start, false, doubt) {
            BoxReading::Face(r) => r,
            other => return other,
        };
        let (roll, k) = (r.roll_degrees.abs(), r.k_measured.abs());
        let rolled_and_sheared = roll > ROLLED_HEAD && k > ROLLED_HEAD_MAX_SHEAR;
        if (roll > NETWORK_DETECTOR_MAX_ROLL || rolled_and_sheared) && r.k.is_some() {
            // Rolled faces found by the network detector are measured from its rough roll,
            // and can be read as less rolled and sheared instead.
            r.k = None;
            r.refused = Some(Refusal::UnreliablePose);
        }
        if window_is_face(logit, &r) {
            BoxReading::Face(r)
        } else {
            BoxReading::NoFace
        }
    }

    /// Whether the network detector finds the faces ([`Detector::Network`](crate::Detector::Network) with the network
    /// locator).
    pub fn uses_network_detector(&self) -> bool {
        self.network_detector().is_some()
    }

    /// Adds to `found` the faces the network detector finds in `gray` (shrunk to at most
    /// `detect_width` columns for the detector; 0: as it is) that `found` lacks, each judged by
    /// the landmark network at full resolution started from the shear `start_k` with
    /// `budget`. Nothing without the network detector.
    pub(crate) fn find_new_faces(
        &self,
        gray: &GrayImage,
        detect_width: u32,
        start_k: f64,
        budget: Budget,
        found: &mut Vec<FoundBox>,
    ) {
        let Some(net) = self.network_detector() else {
            return;
        };
        let (shrunk, scale) = crate::detect::shrunk_to_width(gray, detect_width);
        let min_width = f64::from(self.config.min_face) / scale;
        let windows = network_windows(net, &shrunk, min_width)
            .into_iter()
            .map(|(mut d, logit)| {
                let b = d.face_box;
                d.face_box = Rect::new(b.x * scale, b.y * scale, b.width * scale, b.height * scale);
                (d, logit)
            })
            .collect();
        let doubtful = self.judge_windows(gray, windows, Some(start_k), budget, found);
        self.judge_doubtful_windows(gray, &doubtful, budget, found);
    }

    /// The proposal network when it is the face detector ([`Detector::Network`] with the
    /// network locator, which judges its windows).
    pub(crate) fn network_detector(&self) -> Option<&ProposalNet> {
        let network = self.locator() == Locator::Network;
        self.face_detector.as_ref().filter(|_| network)
    }
}
