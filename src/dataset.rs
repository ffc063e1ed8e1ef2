//! Annotated face data sets: faces with hand-marked eye centres (and, where the set has them,
//! nose and mouth). The loader is a small trait so other annotation formats can be added.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::geometry::Point;

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

/// The Caltech 10,000 Web Faces layout: `ground_truth.txt` with lines
/// `<image> x1 y1 x2 y2 x3 y3 x4 y4` (image-left eye, image-right eye, nose, mouth) and the
/// images in `images/`.
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_caltech_lines() {
        let text = "pic1.jpg 1 2 3 4 5 6 7 8\n\npic2.jpg 1.5e1 2 3 4 5 6 7 8.25\n";
        let faces = CaltechWebFaces::parse(text, Path::new("img")).expect("valid");
        assert_eq!(faces.len(), 2);
        assert_eq!(faces[0].image, Path::new("img/pic1.jpg"));
        assert_eq!(faces[0].right_eye, Point::new(1.0, 2.0));
        assert_eq!(faces[0].left_eye, Point::new(3.0, 4.0));
        assert_eq!(faces[1].right_eye.x, 15.0);
        assert_eq!(faces[1].mouth, Some(Point::new(7.0, 8.25)));
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
}
