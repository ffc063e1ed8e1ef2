//! Equation 6: the shear found (or given) undone on the whole image or on each face region.

use image::DynamicImage;

use super::report::{CorrectOptions, ImageReport, Readout, Region};
use super::Unshear;
use crate::error::{Error, Result};
use crate::geometry::Shear;
use crate::warp;

/// How much a face box is enlarged (each side, as a fraction of its size) to make the region that
/// a face-region correction changes: the margin takes in hair and jaw, and the warp's feathered
/// edge lies outside the face.
pub(crate) const FACE_REGION_MARGIN: f64 = 0.3;

impl Unshear {
    /// The length (pixels) of a horizontal motion blur along `img`'s rows, from the zeros it
    /// leaves in their spectrum ([`crate::deblur::blur_length`], from 4 px up to a quarter of
    /// the width), for [`CorrectOptions::blur`]; `None` when no clear blur shows.
    pub fn find_blur(img: &DynamicImage) -> Option<f64> {
        let gray = crate::detect::to_gray_opencv(img);
        crate::deblur::blur_length(&gray, 0..gray.height(), f64::from(gray.width()) / 4.0)
    }

    /// Removes a horizontal motion blur from `img` in place, before its faces are read
    /// (`correct --deblur`): `length` pixels on every row, or (`None`) each row's length found
    /// in bands of rows ([`crate::deblur::blur_lengths`]: a pan changing speed during the
    /// readout blurs rows differently). Returns the length removed at the middle row, `None`
    /// when no blur was found (`img` unchanged).
    pub fn remove_blur(img: &mut DynamicImage, length: Option<f64>) -> Result<Option<f64>> {
        let h = img.height() as usize;
        let lengths = match length {
            Some(px) => Some(vec![px; h]),
            None => {
                let gray = crate::detect::to_gray_opencv(img);
                crate::deblur::blur_lengths(&gray, f64::from(gray.width()) / 4.0)
            }
        };
        let Some(lengths) = lengths else {
            return Ok(None);
        };
        crate::deblur::deblur_image(img, &lengths, crate::deblur::DEFAULT_NOISE_TO_SIGNAL)?;
        Ok(lengths.get(h / 2).copied())
    }

    /// Undoes the shear found in `report` (or `options.k`) on `img` (equation 6).
    ///
    /// Whole image: rows shifted by `-k (y - H/2)`, or each by its own offset when the report's
    /// shear changes down the rows ([`ImageReport::row_shear`], unless `options.k` is given).
    /// Faces: each face region (its box enlarged by 30% of its size each way) de-sheared about
    /// its own centre with its own `k`, feathered into the untouched surroundings. A report read out by columns ([`Readout::Columns`]) is undone
    /// along the columns: the same warp on the transposed image, columns shifted by
    /// `-k (x - W/2)`. Fails with [`Error::InvalidArgument`] when there is no shear to apply
    /// (no face and no `options.k`) or the shear is not finite. It needs no models (the report
    /// carries all it uses), so it takes no corrector.
    pub fn correct(
        img: &DynamicImage,
        report: &ImageReport,
        options: &CorrectOptions,
    ) -> Result<DynamicImage> {
        if report.readout == Readout::Columns {
            // Transposing swaps rows and columns (and the faces' boxes with them): a vertical
            // shear becomes a horizontal one, undone as any other, and the result is turned back.
            let mut rows = report.clone();
            rows.readout = Readout::Rows;
            (rows.width, rows.height) = (report.height, report.width);
            for f in &mut rows.faces {
                let b = f.face_box;
                f.face_box = crate::geometry::Rect::new(b.y, b.x, b.height, b.width);
            }
            let out = Self::correct(&warp::transpose(img), &rows, options)?;
            return Ok(warp::transpose(&out));
        }
        if let Some(k) = options.k {
            if !k.is_finite() {
                return Err(Error::InvalidArgument(format!("shear {k} is not finite")));
            }
        }
        match options.region {
            Region::Image => {
                let k = options.k.or(report.k).ok_or_else(|| {
                    Error::InvalidArgument("no face found and no shear given".into())
                })?;
                let sharp;
                let src = match options.blur {
                    Some(length) => {
                        // The blur is removed from the rows as read, before they are moved.
                        let mut copy = img.clone();
                        Self::remove_blur(&mut copy, Some(length))?;
                        sharp = copy;
                        &sharp
                    }
                    None => img,
                };
                // Faces at different heights that disagree bend the rows' offsets, unless a
                // shear is given.
                let (interp, canvas) = (options.interpolation, options.canvas);
                match report.row_shear.filter(|_| options.k.is_none()) {
                    Some(rows) => {
                        let pivot = f64::from(img.height()) / 2.0;
                        let shifts = rows.offsets(img.height(), pivot);
                        Ok(warp::try_shift_rows_on(src, &shifts, pivot, interp, canvas)?.0)
                    }
                    None => {
                        let shear = Shear::about_middle(k, img.height());
                        Ok(warp::try_remove_shear(src, shear, interp, canvas)?.0)
                    }
                }
            }
            Region::Face => {
                if report.faces.is_empty() {
                    return Err(Error::InvalidArgument(
                        "no face found: a face-region correction needs a detected face".into(),
                    ));
                }
                let mut out = img.clone();
                for face in &report.faces {
                    let Some(k) = options.k.or(face.k) else {
                        continue;
                    };
                    let b = face.face_box;
                    let region = b.scaled_about_center(1.0 + 2.0 * FACE_REGION_MARGIN);
                    let shear = Shear::new(k, b.center().y);
                    out = warp::remove_shear_in_region(&out, shear, region, options.interpolation);
                }
                Ok(out)
            }
        }
    }
}
