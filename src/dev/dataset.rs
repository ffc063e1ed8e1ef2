//! Annotated face data sets: faces with hand-marked eye centres (and, where the set has them,
//! nose and mouth). The loader is a small trait so other annotation formats can be added.
//!
//! Also here: dlib/imglab 68-point landmark XML ([`DlibLandmarks`], for the nostril check) and
//! identity-labelled sets for recognition ([`celeba_identities`], [`yale_identities`]) with the
//! paper's gallery/probe split ([`gallery_probe_split`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::geometry::{Point, Rect};

fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// One annotated face.
#[derive(Debug, Clone, PartialEq)]
pub struct AnnotatedFace {
    /// The image file.
    pub image: PathBuf,
    /// Subject's right eye centre (image left).
    pub right_eye: Point,
    /// Subject's left eye centre (image right).
    pub left_eye: Point,
    /// Nose point, if annotated.
    pub nose: Option<Point>,
    /// Mouth centre, if annotated.
    pub mouth: Option<Point>,
}

impl AnnotatedFace {
    /// Distance between the eye centres, pixels.
    pub fn eye_distance(&self) -> f64 {
        self.right_eye.distance(self.left_eye)
    }
}

/// A source of annotated faces.
pub trait FaceDataset {
    /// Every annotated face, in a fixed order (so training and evaluation are reproducible).
    fn faces(&self) -> Result<Vec<AnnotatedFace>>;
}

/// The coordinate of the first pixel in Caltech's `ground_truth.txt`: 1.
///
/// The data set does not say, so it was measured. Eye filters trained on the faces and their
/// mirror images, with the annotations read as 0-based, located the eyes of the first 300
/// evaluation faces (eye distance >= 40 px, boxes from the annotated eyes) a median 0.019-0.026
/// eye distances (about a pixel) left of the annotation, for both eyes, while filters trained
/// without the mirror images showed no such shift (0.001-0.003). A mirror maps a 1-based `x` to
/// the wrong side of the pixel, so the two halves of the training set disagreed by a pixel
/// sideways. Read as 1-based, the mirror-trained filters' shift vanishes (0.002-0.007) and
/// more eyes are located within 0.05 eye distances than with any other origin tried.
/// `cargo run --release --example eye_offsets` measures this for the committed filters.
pub const CALTECH_PIXEL_ORIGIN: f64 = 1.0;

/// The Caltech 10,000 Web Faces layout: `ground_truth.txt` with lines
/// `<image> x1 y1 x2 y2 x3 y3 x4 y4` (image-left eye, image-right eye, nose, mouth) and the
/// images in `images/`.
///
/// The file counts pixels from 1 (MATLAB's convention); [`Self::parse`] converts to this crate's
/// convention, where pixel `(0, 0)` is centred on `(0.0, 0.0)`, by subtracting
/// [`CALTECH_PIXEL_ORIGIN`].
#[derive(Debug, Clone)]
pub struct CaltechWebFaces {
    root: PathBuf,
}

impl CaltechWebFaces {
    /// The data set in folder `root` (holding `ground_truth.txt` and `images/`).
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    /// Parses annotation text; `images` is the folder the image names are relative to.
    pub fn parse(text: &str, images: &Path) -> Result<Vec<AnnotatedFace>> {
        let mut faces = Vec::new();
        for (n, line) in text.lines().enumerate() {
            let fields: Vec<&str> = line.split_whitespace().collect();
            if fields.is_empty() {
                continue;
            }
            if fields.len() != 9 {
                return Err(Error::Training(format!(
                    "line {}: expected an image name and 8 numbers, found {} fields",
                    n + 1,
                    fields.len()
                )));
            }
            let mut v = [0f64; 8];
            for (slot, f) in v.iter_mut().zip(&fields[1..]) {
                *slot = f
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| Error::Training(format!("line {}: bad number {f:?}", n + 1)))?;
            }
            v.iter_mut().for_each(|c| *c -= CALTECH_PIXEL_ORIGIN);
            faces.push(AnnotatedFace {
                image: images.join(fields[0]),
                right_eye: Point::new(v[0], v[1]),
                left_eye: Point::new(v[2], v[3]),
                nose: Some(Point::new(v[4], v[5])),
                mouth: Some(Point::new(v[6], v[7])),
            });
        }
        Ok(faces)
    }
}

impl FaceDataset for CaltechWebFaces {
    fn faces(&self) -> Result<Vec<AnnotatedFace>> {
        let path = self.root.join("ground_truth.txt");
        let text = std::fs::read_to_string(&path).map_err(|source| Error::Io {
            path: path.clone(),
            source,
        })?;
        Self::parse(&text, &self.root.join("images"))
    }
}

/// Groups faces by image, images in name order, faces in file order (one decode per image).
pub fn by_image(faces: Vec<AnnotatedFace>) -> Vec<(PathBuf, Vec<AnnotatedFace>)> {
    let mut map: BTreeMap<PathBuf, Vec<AnnotatedFace>> = BTreeMap::new();
    for f in faces {
        map.entry(f.image.clone()).or_default().push(f);
    }
    map.into_iter().collect()
}

/// [`by_image`] kept to the photos all of whose faces have eyes less than `max_eye_distance`
/// apart: the networks' training photos (40 px), which share no photo with the faces the
/// accuracy tables measure (40 px and more).
pub fn photos_with_small_faces(
    faces: Vec<AnnotatedFace>,
    max_eye_distance: f64,
) -> Vec<(PathBuf, Vec<AnnotatedFace>)> {
    by_image(faces)
        .into_iter()
        .filter(|(_, faces)| faces.iter().all(|f| f.eye_distance() < max_eye_distance))
        .collect()
}

/// One face of a 68-point landmark file (iBUG/dlib numbering, 0-based: 36-41 the subject's
/// right eye (image left), 42-47 the left eye, 31-35 the lower nose with the nostrils near 32
/// and 34).
#[derive(Debug, Clone, PartialEq)]
pub struct LandmarkFace {
    /// The image file.
    pub image: PathBuf,
    /// The annotated face box.
    pub face_box: Rect,
    /// The 68 points by index; `None` where the file has no such part.
    pub points: Vec<Option<Point>>,
}

impl LandmarkFace {
    /// Mean of the parts `range` (all must be present).
    fn centroid(&self, range: std::ops::RangeInclusive<usize>) -> Option<Point> {
        let n = range.clone().count() as f64;
        let mut sum = Point::new(0.0, 0.0);
        for i in range {
            let p = (*self.points.get(i)?)?;
            sum = Point::new(sum.x + p.x, sum.y + p.y);
        }
        Some(Point::new(sum.x / n, sum.y / n))
    }

    /// Subject's right eye centre (image left): the mean of points 36-41.
    pub fn right_eye(&self) -> Option<Point> {
        self.centroid(36..=41)
    }

    /// Subject's left eye centre (image right): the mean of points 42-47.
    pub fn left_eye(&self) -> Option<Point> {
        self.centroid(42..=47)
    }

    /// Subject's right nostril (image left): point 32.
    pub fn right_nostril(&self) -> Option<Point> {
        self.points.get(32).copied().flatten()
    }

    /// Subject's left nostril (image right): point 34.
    pub fn left_nostril(&self) -> Option<Point> {
        self.points.get(34).copied().flatten()
    }
}

/// dlib's imglab XML with 68-point `<part>`s per `<box>` (e.g.
/// `examples/faces/*_with_face_landmarks.xml`); image names are relative to the XML's folder.
#[derive(Debug, Clone)]
pub struct DlibLandmarks {
    xml: PathBuf,
}

impl DlibLandmarks {
    /// The landmark file at `xml`.
    pub fn new(xml: impl Into<PathBuf>) -> Self {
        Self { xml: xml.into() }
    }

    /// Parses imglab XML; `base` is the folder image names are relative to. Boxes marked
    /// `ignore='1'` are skipped; a malformed number is an error (not silently a zero).
    pub fn parse(text: &str, base: &Path) -> Result<Vec<LandmarkFace>> {
        let doc = roxmltree::Document::parse(text)
            .map_err(|e| Error::Training(format!("landmark XML: {e}")))?;
        let num = |node: roxmltree::Node, name: &str| -> Result<f64> {
            node.attribute(name)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    Error::Training(format!(
                        "landmark XML: <{}> without a valid '{name}'",
                        node.tag_name().name()
                    ))
                })
        };
        let mut faces = Vec::new();
        for image in doc.descendants().filter(|n| n.has_tag_name("image")) {
            let Some(file) = image.attribute("file") else {
                return Err(Error::Training(
                    "landmark XML: <image> without 'file'".into(),
                ));
            };
            for b in image.children().filter(|n| n.has_tag_name("box")) {
                if b.attribute("ignore") == Some("1") {
                    continue;
                }
                let face_box = Rect::new(
                    num(b, "left")?,
                    num(b, "top")?,
                    num(b, "width")?,
                    num(b, "height")?,
                );
                let mut points = vec![None; 68];
                for part in b.children().filter(|n| n.has_tag_name("part")) {
                    let idx = part
                        .attribute("name")
                        .and_then(|v| v.trim().parse::<usize>().ok())
                        .filter(|&i| i < 68);
                    if let Some(i) = idx {
                        points[i] = Some(Point::new(num(part, "x")?, num(part, "y")?));
                    }
                }
                faces.push(LandmarkFace {
                    image: base.join(file),
                    face_box,
                    points,
                });
            }
        }
        Ok(faces)
    }

    /// Every face of the file.
    pub fn faces(&self) -> Result<Vec<LandmarkFace>> {
        let base = self.xml.parent().unwrap_or(Path::new("."));
        Self::parse(&read_text(&self.xml)?, base)
    }
}

/// An image with the identity of the person in it.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct LabelledImage {
    /// Identity label.
    pub identity: String,
    /// The image file.
    pub image: PathBuf,
}

/// Parses `identity.txt` lines `<image> <identity>` (CelebA); images relative to `images`.
pub fn parse_identity_list(text: &str, images: &Path) -> Result<Vec<LabelledImage>> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        match fields.as_slice() {
            [] => {}
            [image, identity] => out.push(LabelledImage {
                identity: (*identity).to_string(),
                image: images.join(image),
            }),
            _ => {
                return Err(Error::Training(format!(
                    "identity list line {}: expected `<image> <identity>`",
                    n + 1
                )))
            }
        }
    }
    Ok(out)
}

/// The CelebA subset: `root/identity.txt` and `root/images/`.
pub fn celeba_identities(root: &Path) -> Result<Vec<LabelledImage>> {
    parse_identity_list(
        &read_text(&root.join("identity.txt"))?,
        &root.join("images"),
    )
}

/// The LFW subset: `root/identity.txt` and `root/images/`.
pub fn lfw_identities(root: &Path) -> Result<Vec<LabelledImage>> {
    parse_identity_list(
        &read_text(&root.join("identity.txt"))?,
        &root.join("images"),
    )
}

/// Whether the networks may train on the LFW subset's identity `name`, `identities` being the
/// subset's images ([`lfw_identities`], any order): the split is by identity, so that no person
/// trained on is ever measured. The distinct identity names are sorted (byte order); those at
/// even positions (0, 2, 4, ...: 40 of the 79) are trained on (the landmark network's
/// shear-only faces, `dev::landmark_crops::extra_faces`), those at odd positions never are and
/// are kept for a recognition table on LFW (issue 61), which must measure only them
/// (`!lfw_trained_identity(..)`). A name that is not in `identities` is not trained on.
pub fn lfw_trained_identity(identities: &[LabelledImage], name: &str) -> bool {
    let names: std::collections::BTreeSet<&str> =
        identities.iter().map(|i| i.identity.as_str()).collect();
    names
        .iter()
        .position(|n| *n == name)
        .is_some_and(|i| i % 2 == 0)
}

/// The Yale faces: `root/images/subjectNN.condition.jpeg`, identity `subjectNN` (the part of the
/// file name before the first dot). Files without a dot in the name are skipped.
pub fn yale_identities(root: &Path) -> Result<Vec<LabelledImage>> {
    let dir = root.join("images");
    let entries = std::fs::read_dir(&dir).map_err(|source| Error::Io {
        path: dir.clone(),
        source,
    })?;
    let mut out = Vec::new();
    for e in entries {
        let e = e.map_err(|source| Error::Io {
            path: dir.clone(),
            source,
        })?;
        let name = e.file_name().to_string_lossy().into_owned();
        if let Some((identity, _)) = name.split_once('.') {
            out.push(LabelledImage {
                identity: identity.to_string(),
                image: e.path(),
            });
        }
    }
    Ok(out)
}

/// The paper's protocol: per identity, the first `gallery` images by file name are the gallery,
/// the rest probes. Returns `(gallery, probes)`, both sorted by identity then file name.
/// Identities with no probe left still enrol (they are possible wrong answers).
pub fn gallery_probe_split(
    mut items: Vec<LabelledImage>,
    gallery: usize,
) -> (Vec<LabelledImage>, Vec<LabelledImage>) {
    items.sort_by(|a, b| {
        (a.identity.as_str(), a.image.file_name()).cmp(&(b.identity.as_str(), b.image.file_name()))
    });
    let (mut g, mut p) = (Vec::new(), Vec::new());
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    for item in items {
        let n = seen.entry(item.identity.clone()).or_default();
        *n += 1;
        if *n <= gallery {
            g.push(item);
        } else {
            p.push(item);
        }
    }
    (g, p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_first_three_by_file_name() {
        let li = |id: &str, f: &str| LabelledImage {
            identity: id.into(),
            image: PathBuf::from("x").join(f),
        };
        let items = vec![
            li("a", "5.jpg"),
            li("a", "1.jpg"),
            li("b", "9.jpg"),
            li("a", "3.jpg"),
            li("a", "2.jpg"),
            li("a", "4.jpg"),
        ];
        let (g, p) = gallery_probe_split(items, 3);
        let names = |v: &[LabelledImage]| {
            v.iter()
                .map(|i| {
                    format!(
                        "{}/{}",
                        i.identity,
                        i.image.file_name().unwrap().to_string_lossy()
                    )
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(names(&g), ["a/1.jpg", "a/2.jpg", "a/3.jpg", "b/9.jpg"]);
        assert_eq!(names(&p), ["a/4.jpg", "a/5.jpg"]);
    }

    #[test]
    fn lfw_trains_on_the_identities_at_even_sorted_positions() {
        let items = parse_identity_list(
            "c1.jpg Carol\nb0.jpg Bob\na0.jpg Alice\nd0.jpg Dave\nb1.jpg Bob\nc0.jpg Carol\n",
            Path::new("images"),
        )
        .expect("parse");
        // Sorted distinct names: Alice (0), Bob (1), Carol (2), Dave (3).
        let trained: Vec<bool> = ["Alice", "Bob", "Carol", "Dave", "Eve"]
            .iter()
            .map(|n| lfw_trained_identity(&items, n))
            .collect();
        assert_eq!(trained, [true, false, true, false, false]);
        // The order of the file and repeated names change nothing.
        let mut reversed = items.clone();
        reversed.reverse();
        assert!(
            lfw_trained_identity(&reversed, "Carol") && !lfw_trained_identity(&reversed, "Bob")
        );
    }

    /// On the shared data (skipped without it): 40 of the 79 identities are trained on, their
    /// 697 of the 1373 photos.
    #[test]
    fn lfw_subset_split_on_the_shared_data() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/lfw-subset");
        let Ok(items) = lfw_identities(&root) else {
            eprintln!("skipped: no {}", root.display());
            return;
        };
        let names: std::collections::BTreeSet<&str> =
            items.iter().map(|i| i.identity.as_str()).collect();
        let trained = names
            .iter()
            .filter(|n| lfw_trained_identity(&items, n))
            .count();
        let photos = items
            .iter()
            .filter(|i| lfw_trained_identity(&items, &i.identity))
            .count();
        assert_eq!(
            (names.len(), trained, items.len(), photos),
            (79, 40, 1373, 697)
        );
    }

    #[test]
    fn yale_identity_is_the_name_before_the_first_dot() {
        let dir = tempfile::tempdir().expect("tempdir");
        let images = dir.path().join("images");
        std::fs::create_dir(&images).expect("mkdir");
        for f in ["subject02.sad.jpeg", "subject01.glasses.jpeg", "README"] {
            std::fs::write(images.join(f), b"").expect("write");
        }
        let mut l = yale_identities(dir.path()).expect("listing");
        l.sort();
        assert_eq!(l.len(), 2);
        assert_eq!(l[0].identity, "subject01");
        assert_eq!(l[1].image, images.join("subject02.sad.jpeg"));
        assert!(yale_identities(&dir.path().join("missing")).is_err());
    }

    #[test]
    fn parses_identity_list_and_rejects_bad_lines() {
        let l = parse_identity_list("a.jpg 7\n\nb.jpg 8\n", Path::new("img")).expect("valid");
        assert_eq!(l.len(), 2);
        assert_eq!(l[1].identity, "8");
        assert_eq!(l[0].image, Path::new("img/a.jpg"));
        assert!(parse_identity_list("a.jpg", Path::new(".")).is_err());
    }

    #[test]
    fn parses_dlib_landmarks() {
        let mut parts = String::new();
        for i in 0..68 {
            parts.push_str(&format!("<part name='{i:02}' x='{}' y='{}'/>", i, 2 * i));
        }
        let xml = format!(
            "<dataset><images><image file='p.jpg'><box top='1' left='2' width='3' height='4'>{parts}</box><box top='1' left='2' width='3' height='4' ignore='1'/></image></images></dataset>"
        );
        let f = DlibLandmarks::parse(&xml, Path::new("d")).expect("valid");
        assert_eq!(f.len(), 1);
        assert_eq!(f[0].image, Path::new("d/p.jpg"));
        assert_eq!(f[0].face_box, Rect::new(2.0, 1.0, 3.0, 4.0));
        assert_eq!(f[0].right_eye(), Some(Point::new(38.5, 77.0)));
        assert_eq!(f[0].left_eye(), Some(Point::new(44.5, 89.0)));
        assert_eq!(f[0].right_nostril(), Some(Point::new(32.0, 64.0)));
        assert!(DlibLandmarks::parse("<dataset><images><image file='p'><box top='x' left='1' width='1' height='1'/></image></images></dataset>", Path::new(".")).is_err());
    }

    #[test]
    fn parses_caltech_lines() {
        let text = "pic1.jpg 1 2 3 4 5 6 7 8\n\npic2.jpg 1.5e1 2 3 4 5 6 7 8.25\n";
        let faces = CaltechWebFaces::parse(text, Path::new("img")).expect("valid");
        assert_eq!(faces.len(), 2);
        assert_eq!(faces[0].image, Path::new("img/pic1.jpg"));
        // 1-based in the file, 0-based here.
        assert_eq!(faces[0].right_eye, Point::new(0.0, 1.0));
        assert_eq!(faces[0].left_eye, Point::new(2.0, 3.0));
        assert_eq!(faces[0].nose, Some(Point::new(4.0, 5.0)));
        assert_eq!(faces[1].right_eye.x, 14.0);
        assert_eq!(faces[1].mouth, Some(Point::new(6.0, 7.25)));
    }

    #[test]
    fn rejects_malformed_lines() {
        assert!(CaltechWebFaces::parse("a.jpg 1 2 3", Path::new(".")).is_err());
        assert!(CaltechWebFaces::parse("a.jpg 1 2 3 4 5 6 7 x", Path::new(".")).is_err());
        assert!(CaltechWebFaces::parse("a.jpg 1 2 3 4 5 6 7 NaN", Path::new(".")).is_err());
    }

    #[test]
    fn groups_by_image_in_name_order() {
        let f = |name: &str, x: f64| AnnotatedFace {
            image: PathBuf::from(name),
            right_eye: Point::new(x, 0.0),
            left_eye: Point::new(x + 1.0, 0.0),
            nose: None,
            mouth: None,
        };
        let groups = by_image(vec![f("b", 1.0), f("a", 2.0), f("b", 3.0)]);
        assert_eq!(groups.len(), 2);
        assert_eq!(groups[0].0, PathBuf::from("a"));
        assert_eq!(groups[1].1.len(), 2);
        assert_eq!(groups[1].1[1].right_eye.x, 3.0);
    }

    #[test]
    fn small_face_photos_are_those_without_a_face_at_the_limit() {
        let face = |image: &str, distance: f64| AnnotatedFace {
            image: PathBuf::from(image),
            right_eye: Point::new(0.0, 0.0),
            left_eye: Point::new(distance, 0.0),
            nose: None,
            mouth: None,
        };
        let faces = vec![
            face("b", 20.0),
            face("a", 39.0),
            face("b", 40.0),
            face("c", 10.0),
        ];
        let kept: Vec<PathBuf> = photos_with_small_faces(faces, 40.0)
            .into_iter()
            .map(|(p, _)| p)
            .collect();
        assert_eq!(kept, [PathBuf::from("a"), PathBuf::from("c")]);
    }
}
