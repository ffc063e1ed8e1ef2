//! Points, boxes and the shear convention shared by every module.
//!
//! Convention (kept exact: other tools depend on it): a point `(x, y)` of the undistorted image
//! appears at `x' = x + k * (y - c)`, `y' = y`, where `c` is the pivot row. `k > 0` when rows further
//! down are displaced further right. The default pivot is the image's middle row, `c = H / 2`.

use serde::{Deserialize, Serialize};

/// A point in image pixels (origin top-left, x right, y down; pixel centres at integers).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    /// Column.
    pub x: f64,
    /// Row.
    pub y: f64,
}

impl Point {
    /// A point at `(x, y)`.
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    /// Euclidean distance to `other`.
    pub fn distance(self, other: Point) -> f64 {
        (self.x - other.x).hypot(self.y - other.y)
    }

    /// The midpoint of `self` and `other`.
    pub fn midpoint(self, other: Point) -> Point {
        Point::new((self.x + other.x) / 2.0, (self.y + other.y) / 2.0)
    }
}

/// An axis-aligned box in image pixels: top-left corner and size.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Rect {
    /// Left edge.
    pub x: f64,
    /// Top edge.
    pub y: f64,
    /// Width (> 0 for a real box).
    pub width: f64,
    /// Height (> 0 for a real box).
    pub height: f64,
}

impl Rect {
    /// A box from its top-left corner and size.
    pub const fn new(x: f64, y: f64, width: f64, height: f64) -> Self {
        Self {
            x,
            y,
            width,
            height,
        }
    }

    /// The centre of the box.
    pub fn center(&self) -> Point {
        Point::new(self.x + self.width / 2.0, self.y + self.height / 2.0)
    }

    /// The box scaled by `factor` about its centre (`factor > 1` grows it; `factor` 1 returns
    /// the box exactly).
    pub fn scaled_about_center(&self, factor: f64) -> Rect {
        let (w, h) = (self.width * factor, self.height * factor);
        Rect::new(
            self.x + (self.width - w) / 2.0,
            self.y + (self.height - h) / 2.0,
            w,
            h,
        )
    }

    /// Area (zero for an empty box).
    pub fn area(&self) -> f64 {
        self.width.max(0.0) * self.height.max(0.0)
    }

    /// The overlap of two boxes, or `None` if they do not overlap.
    pub fn intersection(&self, other: &Rect) -> Option<Rect> {
        let x0 = self.x.max(other.x);
        let y0 = self.y.max(other.y);
        let x1 = (self.x + self.width).min(other.x + other.width);
        let y1 = (self.y + self.height).min(other.y + other.height);
        (x1 > x0 && y1 > y0).then(|| Rect::new(x0, y0, x1 - x0, y1 - y0))
    }

    /// Intersection over union, in `[0, 1]`.
    pub fn iou(&self, other: &Rect) -> f64 {
        let inter = self.intersection(other).map_or(0.0, |r| r.area());
        let union = self.area() + other.area() - inter;
        if union > 0.0 {
            inter / union
        } else {
            0.0
        }
    }

    /// Whether `p` lies inside the box (edges included).
    pub fn contains(&self, p: Point) -> bool {
        p.x >= self.x && p.x <= self.x + self.width && p.y >= self.y && p.y <= self.y + self.height
    }
}

/// A horizontal shear about a pivot row: `x' = x + k * (y - pivot_y)`, `y' = y`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shear {
    /// The shear parameter `k` (dimensionless).
    pub k: f64,
    /// The row that does not move.
    pub pivot_y: f64,
}

impl Shear {
    /// A shear with parameter `k` about row `pivot_y`.
    pub const fn new(k: f64, pivot_y: f64) -> Self {
        Self { k, pivot_y }
    }

    /// The default pivot for an image of `height` rows: its middle row, `H / 2`.
    pub fn about_middle(k: f64, height: u32) -> Self {
        Self::new(k, f64::from(height) / 2.0)
    }

    /// Where an undistorted point appears in the sheared image.
    pub fn apply(&self, p: Point) -> Point {
        Point::new(p.x + self.k * (p.y - self.pivot_y), p.y)
    }

    /// Where a point of the sheared image was in the undistorted image (equation 6).
    pub fn invert(&self, p: Point) -> Point {
        Point::new(p.x - self.k * (p.y - self.pivot_y), p.y)
    }

    /// The horizontal displacement of row `y`.
    pub fn row_shift(&self, y: f64) -> f64 {
        self.k * (y - self.pivot_y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shear_moves_lower_rows_right_for_positive_k() {
        let s = Shear::new(0.5, 10.0);
        assert_eq!(s.apply(Point::new(3.0, 10.0)), Point::new(3.0, 10.0));
        assert_eq!(s.apply(Point::new(3.0, 20.0)), Point::new(8.0, 20.0));
        assert_eq!(s.apply(Point::new(3.0, 0.0)), Point::new(-2.0, 0.0));
    }

    #[test]
    fn invert_undoes_apply() {
        let s = Shear::about_middle(-0.37, 481);
        let p = Point::new(12.25, 400.5);
        let q = s.invert(s.apply(p));
        assert!((q.x - p.x).abs() < 1e-12 && q.y == p.y);
    }

    #[test]
    fn scaling_about_the_center_keeps_the_center() {
        let b = Rect::new(10.0, 20.0, 40.0, 60.0);
        assert_eq!(b.scaled_about_center(1.5), Rect::new(0.0, 5.0, 60.0, 90.0));
        assert_eq!(
            b.scaled_about_center(0.5),
            Rect::new(20.0, 35.0, 20.0, 30.0)
        );
        assert_eq!(b.scaled_about_center(1.0), b);
    }

    #[test]
    fn iou_of_known_boxes() {
        let a = Rect::new(0.0, 0.0, 10.0, 10.0);
        let b = Rect::new(5.0, 0.0, 10.0, 10.0);
        assert!((a.iou(&b) - 50.0 / 150.0).abs() < 1e-12);
        assert_eq!(a.iou(&Rect::new(20.0, 20.0, 1.0, 1.0)), 0.0);
        assert!((a.iou(&a) - 1.0).abs() < 1e-12);
    }
}
