//! Photos as files, the common case: read with their EXIF orientation applied (a phone's
//! upright photo read along its sensor's columns), corrected, and written with their colour
//! profile and EXIF block, as the command line does.

use std::path::Path;

use super::report::{CorrectOptions, ImageReport};
use super::Unshear;
use crate::error::{Error, Result};
use crate::imageio::{self, WriteOptions};

/// How [`Unshear::correct_file`] reads and writes.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct FileOptions {
    /// Largest image read, in pixels (checked before decoding).
    pub max_pixels: u64,
    /// Whether an existing output file is replaced (the input never is).
    pub overwrite: bool,
    /// JPEG quality of the output, 1 to 100.
    pub jpeg_quality: u8,
}

impl Default for FileOptions {
    /// [`imageio::DEFAULT_MAX_PIXELS`], no overwriting, quality 95 (the command line's).
    fn default() -> Self {
        let write = WriteOptions::default();
        Self {
            max_pixels: imageio::DEFAULT_MAX_PIXELS,
            overwrite: write.overwrite,
            jpeg_quality: write.jpeg_quality,
        }
    }
}

impl Unshear {
    /// Reads the image file `path` (at most [`imageio::DEFAULT_MAX_PIXELS`]) and estimates the
    /// shear from its faces as [`Self::estimate_photo`] does: the EXIF orientation applied and,
    /// for a photo turned a quarter, the shear read along the sensor's columns.
    pub fn estimate_file(&self, path: impl AsRef<Path>) -> Result<ImageReport> {
        let (img, metadata) =
            imageio::read_image_with_metadata(path.as_ref(), imageio::DEFAULT_MAX_PIXELS)?;
        Ok(self.estimate_photo(&img, &metadata))
    }

    /// Corrects the image file `src` into `dst` as `unshear correct` does: estimated as by
    /// [`Self::estimate_file`], corrected by [`Unshear::correct`] with `options`, and written
    /// atomically in the format `dst`'s extension names, with `src`'s colour profile and EXIF
    /// block, never over `src`. Returns the estimate. Fails with [`Error::InvalidArgument`],
    /// writing nothing, when there is nothing to correct by (no accepted estimate and no
    /// `options.k`) or `dst`'s format is not one written.
    pub fn correct_file(
        &self,
        src: impl AsRef<Path>,
        dst: impl AsRef<Path>,
        options: &CorrectOptions,
        file: &FileOptions,
    ) -> Result<ImageReport> {
        let (src, dst) = (src.as_ref(), dst.as_ref());
        if !imageio::output_format_supported(dst) {
            return Err(Error::InvalidArgument(format!(
                "{}: not an image format that is written",
                dst.display()
            )));
        }
        let (img, metadata) = imageio::read_image_with_metadata(src, file.max_pixels)?;
        let report = self.estimate_photo(&img, &metadata);
        if !options.changes(&report) {
            return Err(Error::InvalidArgument(format!(
                "{}: no face gave an accepted estimate and no shear was given: nothing to \
                 correct by",
                src.display()
            )));
        }
        let fixed = Self::correct(&img, &report, options)?;
        // The input is not needed any more: freed before encoding, for the peak memory.
        drop(img);
        let write = WriteOptions {
            overwrite: file.overwrite,
            protected: vec![src.to_path_buf()],
            jpeg_quality: file.jpeg_quality,
            metadata,
        };
        imageio::write_image_atomic(&fixed, dst, write)?;
        Ok(report)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Config;
    use image::{DynamicImage, Rgb, RgbImage};

    fn corrector() -> Unshear {
        Unshear::new(Config::default()).expect("built-in models")
    }

    fn blank_photo(dir: &Path) -> std::path::PathBuf {
        let path = dir.join("blank.png");
        DynamicImage::ImageRgb8(RgbImage::from_pixel(64, 48, Rgb([90, 90, 90])))
            .save(&path)
            .expect("written");
        path
    }

    #[test]
    fn a_photo_without_faces_is_estimated_and_not_corrected_without_a_shear() {
        let dir = tempfile::tempdir().expect("temp dir");
        let src = blank_photo(dir.path());
        let u = corrector();
        let report = u.estimate_file(&src).expect("read");
        assert!(report.faces.is_empty() && report.k.is_none());
        let dst = dir.path().join("out.png");
        let err = u.correct_file(
            &src,
            &dst,
            &CorrectOptions::default(),
            &FileOptions::default(),
        );
        assert!(matches!(err, Err(Error::InvalidArgument(_))), "{err:?}");
        assert!(!dst.exists(), "nothing written");
    }

    #[test]
    fn a_given_shear_is_applied_and_written_never_over_the_input() {
        let dir = tempfile::tempdir().expect("temp dir");
        let src = blank_photo(dir.path());
        let u = corrector();
        let options = CorrectOptions {
            k: Some(0.2),
            ..CorrectOptions::default()
        };
        let dst = dir.path().join("out.jpg");
        u.correct_file(&src, &dst, &options, &FileOptions::default())
            .expect("written");
        let out = image::open(&dst).expect("a JPEG");
        assert_eq!((out.width(), out.height()), (64, 48));
        // A second write is refused without `overwrite`, and the input is never written.
        assert!(u
            .correct_file(&src, &dst, &options, &FileOptions::default())
            .is_err());
        let over_input = FileOptions {
            overwrite: true,
            ..FileOptions::default()
        };
        assert!(u.correct_file(&src, &src, &options, &over_input).is_err());
        let unknown = dir.path().join("out.xyz");
        assert!(matches!(
            u.correct_file(&src, &unknown, &options, &FileOptions::default()),
            Err(Error::InvalidArgument(_))
        ));
        assert!(matches!(
            u.estimate_file(dir.path().join("missing.png")),
            Err(Error::Io { .. })
        ));
    }
}
