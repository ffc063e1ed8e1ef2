//! Reading and writing images.
//!
//! * Reading detects the format from the content (not the extension), checks the declared size
//!   against a pixel limit *before* decoding (so a hostile 100000 x 100000 header costs nothing),
//!   bounds the decoder's allocations, and applies the EXIF orientation so faces are upright.
//! * Writing picks the format from the output extension, converts channels only where the format
//!   cannot store them, writes to a temporary file in the destination folder and renames it into
//!   place (atomic: readers never see a half-written file), and never overwrites an input.

use crate::{Error, Result};
use image::codecs::jpeg::JpegEncoder;
use image::codecs::pnm::{PnmEncoder, PnmSubtype, SampleEncoding};
use image::{DynamicImage, ImageDecoder, ImageReader, Limits};
use std::borrow::Cow;
use std::io::{BufRead, BufWriter, Cursor, Seek, Write};
use std::path::{Path, PathBuf};

/// Default decoded-size limit: 250 megapixels. Generous enough for 100-megapixel medium-format
/// photos and large panoramas, yet it stops decompression bombs (250 MP of 8-bit RGB is 750 MB).
pub const DEFAULT_MAX_PIXELS: u64 = 250_000_000;

/// Bytes per pixel of the widest decoded layout (`Rgba32F`): the allocation bound handed to the
/// decoders is `max_pixels` times this (plus slack for decoder state).
const MAX_BYTES_PER_PIXEL: u64 = 16;

/// Read an image file, detecting its format from the content.
///
/// The declared dimensions are checked against `max_pixels` before any pixel is decoded
/// ([`Error::TooLarge`]), and the decoder's allocations are bounded accordingly; so is the file
/// itself (`max_file_bytes`), which matters for devices and pipes. The EXIF orientation (JPEG,
/// TIFF, WebP) is applied, so the result is upright; a missing or unreadable orientation tag is
/// treated as "no transform".
///
/// # Errors
/// [`Error::Io`] if the file cannot be opened, [`Error::Image`] if the format is unknown or the
/// data is corrupt, [`Error::TooLarge`] if the image exceeds `max_pixels` or the file
/// `max_file_bytes`.
pub fn read_image(path: &Path, max_pixels: u64) -> Result<DynamicImage> {
    read_image_with_metadata(path, max_pixels).map(|(img, _)| img)
}

/// [`read_image`], also returning the file's colour profile and EXIF block ([`Metadata`]) so a
/// corrected photo can be written with them ([`WriteOptions::metadata`]).
///
/// # Errors
/// As [`read_image`]. Unreadable metadata is not an error: it is left out.
pub fn read_image_with_metadata(path: &Path, max_pixels: u64) -> Result<(DynamicImage, Metadata)> {
    let bytes = read_bounded(path, max_file_bytes(max_pixels))?;
    check_complete(&bytes, path)?;
    let open = || ImageReader::new(Cursor::new(bytes.as_slice())).with_guessed_format();
    decode(open, max_pixels, path)
}

/// The largest image file [`read_image`] reads for a `max_pixels` limit: 8 bytes per pixel (a
/// 16-bit RGBA image stored uncompressed) plus 16 MiB for headers and metadata. Nothing larger
/// can hold an image within the limit, and a device such as `/dev/zero` or an endless pipe is
/// cut off there instead of filling the memory.
pub(crate) fn max_file_bytes(max_pixels: u64) -> u64 {
    max_pixels.saturating_mul(8).saturating_add(16 << 20)
}

/// The whole of `path`, or [`Error::TooLarge`] when it holds more than `limit` bytes.
fn read_bounded(path: &Path, limit: u64) -> Result<Vec<u8>> {
    use std::io::Read;
    let io_err = |source| Error::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io_err)?;
    // The size of a regular file sizes the buffer; devices and pipes report none.
    let known = file
        .metadata()
        .ok()
        .filter(|m| m.is_file())
        .map(|m| m.len());
    let mut bytes = Vec::with_capacity(known.unwrap_or(0).min(limit) as usize);
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(io_err)?;
    if bytes.len() as u64 > limit {
        return Err(Error::FileTooLarge {
            path: path.to_path_buf(),
            limit,
        });
    }
    Ok(bytes)
}

/// Rejects a JPEG that stops before its end-of-image marker. The JPEG decoder, like libjpeg,
/// pads a truncated scan with grey and reports success; a half-transferred camera frame must
/// instead be reported, not silently measured.
fn check_complete(bytes: &[u8], path: &Path) -> Result<()> {
    if !bytes.starts_with(&[0xFF, 0xD8]) {
        return Ok(());
    }
    // The last start-of-scan marker; an end-of-image marker must follow it. (Entropy-coded data
    // cannot contain FF D9: an FF there is always followed by 00 or a restart marker.)
    let Some(sos) = bytes.windows(2).rposition(|w| w == [0xFF, 0xDA]) else {
        return Ok(());
    };
    if bytes[sos..].windows(2).any(|w| w == [0xFF, 0xD9]) {
        return Ok(());
    }
    Err(Error::Image {
        path: path.to_path_buf(),
        source: image::ImageError::Decoding(image::error::DecodingError::new(
            image::error::ImageFormatHint::Exact(image::ImageFormat::Jpeg),
            "truncated JPEG: the data ends before the end-of-image marker",
        )),
    })
}

/// [`read_image`] from bytes in memory (for tests and fuzzing); errors name the path `<memory>`.
///
/// # Errors
/// As [`read_image`].
pub fn read_image_from_memory(bytes: &[u8], max_pixels: u64) -> Result<DynamicImage> {
    read_image_with_metadata_from_memory(bytes, max_pixels).map(|(img, _)| img)
}

/// [`read_image_with_metadata`] from bytes in memory (an upload, say): the same checks and
/// limits, the same [`Metadata`]; errors name the path `<memory>`.
///
/// # Errors
/// As [`read_image`].
pub fn read_image_with_metadata_from_memory(
    bytes: &[u8],
    max_pixels: u64,
) -> Result<(DynamicImage, Metadata)> {
    check_complete(bytes, Path::new("<memory>"))?;
    let open = || ImageReader::new(Cursor::new(bytes)).with_guessed_format();
    decode(open, max_pixels, Path::new("<memory>"))
}

/// Decode with the size check; `open` makes a fresh reader (a second one is needed only when the
/// decoder refuses the header under the allocation limit, to report the declared size).
fn decode<R: BufRead + Seek>(
    open: impl Fn() -> std::io::Result<ImageReader<R>>,
    max_pixels: u64,
    path: &Path,
) -> Result<(DynamicImage, Metadata)> {
    let io_err = |source| Error::Io {
        path: path.to_path_buf(),
        source,
    };
    let image_err = |source| Error::Image {
        path: path.to_path_buf(),
        source,
    };
    let too_large = |(width, height): (u32, u32)| {
        let pixels = u64::from(width) * u64::from(height);
        (pixels > max_pixels).then_some(Error::TooLarge {
            width,
            height,
            pixels,
            limit: max_pixels,
        })
    };
    let mut reader = open().map_err(io_err)?;
    let is_tiff = reader.format() == Some(image::ImageFormat::Tiff);
    let mut limits = Limits::default();
    limits.max_alloc = Some(
        max_pixels
            .saturating_mul(MAX_BYTES_PER_PIXEL)
            .saturating_add(64 << 20),
    );
    reader.limits(limits);
    // Building the decoder reads only the header (JPEG: the file into memory, undecoded).
    let mut decoder = match reader.into_decoder() {
        Ok(d) => d,
        Err(e @ image::ImageError::Limits(_)) => {
            // Some decoders (PNG) already refuse the header under the allocation limit: read the
            // declared size without limits (header only) so the error says what is wrong.
            let mut unlimited = open().map_err(io_err)?;
            unlimited.no_limits();
            let dims = unlimited.into_dimensions().map_err(image_err)?;
            return Err(too_large(dims).unwrap_or_else(|| image_err(e)));
        }
        Err(e @ image::ImageError::Unsupported(_)) if is_tiff => {
            let inner = open().map_err(io_err)?.into_inner();
            return match grey_alpha_tiff(inner, max_pixels) {
                Some(Ok((img, orientation))) => Ok((
                    img,
                    Metadata {
                        turned: turned_by(orientation),
                        ..Metadata::default()
                    },
                )),
                Some(Err(dims)) => Err(too_large(dims).unwrap_or_else(|| image_err(e))),
                None => Err(image_err(e)),
            };
        }
        Err(e) => return Err(image_err(e)),
    };
    if let Some(e) = too_large(decoder.dimensions()) {
        return Err(e);
    }
    // A corrupt EXIF block or profile must not make an otherwise good photo unreadable.
    let icc_profile = decoder.icc_profile().ok().flatten();
    let mut exif = decoder.exif_metadata().ok().flatten();
    let orientation = decoder
        .orientation()
        .unwrap_or(image::metadata::Orientation::NoTransforms);
    let mut img = DynamicImage::from_decoder(decoder).map_err(image_err)?;
    img.apply_orientation(orientation);
    if let Some(exif) = exif.as_mut() {
        // The pixels are upright now: a copied orientation tag would turn them again.
        let _ = image::metadata::Orientation::remove_from_exif_chunk(exif);
    }
    let metadata = Metadata {
        icc_profile: icc_profile.filter(|p| !p.is_empty()),
        exif: exif.filter(|e| !e.is_empty()),
        turned: turned_by(orientation),
    };
    Ok((img, metadata))
}

/// Whether `orientation` turns the pixels a quarter ([`Metadata::turned`]).
fn turned_by(orientation: image::metadata::Orientation) -> bool {
    use image::metadata::Orientation::{Rotate270, Rotate270FlipH, Rotate90, Rotate90FlipH};
    matches!(
        orientation,
        Rotate90 | Rotate270 | Rotate90FlipH | Rotate270FlipH
    )
}

/// A grey-with-alpha TIFF (8 or 16 bits, black is zero), which the `image` crate refuses: the
/// `tiff` crate reports grey with an extra sample as "multiband", and `image` knows no such
/// colour type. `None` when the file is not one or cannot be decoded (the caller reports the
/// `image` crate's error), `Some(Err(dimensions))` when it holds more than `max_pixels`. The
/// orientation tag is applied and returned.
fn grey_alpha_tiff<R: std::io::Read + Seek>(
    r: R,
    max_pixels: u64,
) -> Option<std::result::Result<(DynamicImage, image::metadata::Orientation), (u32, u32)>> {
    use tiff::decoder::{Decoder, DecodingResult, Limits as TiffLimits};
    use tiff::tags::{PhotometricInterpretation, Tag};
    let mut decoder = Decoder::new(r).ok()?;
    let (width, height) = decoder.dimensions().ok()?;
    let two_samples = matches!(
        decoder.colortype().ok()?,
        tiff::ColorType::Multiband {
            bit_depth: 8 | 16,
            num_samples: 2
        } | tiff::ColorType::GrayA(8 | 16)
    );
    let photometric = decoder
        .find_tag_unsigned::<u16>(Tag::PhotometricInterpretation)
        .ok()??;
    if !two_samples || photometric != PhotometricInterpretation::BlackIsZero.to_u16() {
        return None;
    }
    if u64::from(width) * u64::from(height) > max_pixels {
        return Some(Err((width, height)));
    }
    let mut limits = TiffLimits::default();
    // Two 16-bit samples a pixel at most.
    limits.decoding_buffer_size =
        usize::try_from(max_pixels.saturating_mul(4)).unwrap_or(usize::MAX);
    let orientation = decoder
        .find_tag_unsigned::<u8>(Tag::Orientation)
        .ok()
        .flatten()
        .and_then(image::metadata::Orientation::from_exif)
        .unwrap_or(image::metadata::Orientation::NoTransforms);
    let mut img = match decoder.with_limits(limits).read_image().ok()? {
        DecodingResult::U8(v) => {
            DynamicImage::ImageLumaA8(image::ImageBuffer::from_raw(width, height, v)?)
        }
        DecodingResult::U16(v) => {
            DynamicImage::ImageLumaA16(image::ImageBuffer::from_raw(width, height, v)?)
        }
        _ => return None,
    };
    img.apply_orientation(orientation);
    Some(Ok((img, orientation)))
}

/// What a photo file says about its pixels besides the pixels: carried from the file read
/// ([`read_image_with_metadata`]) to the corrected file written ([`WriteOptions::metadata`]) so
/// that colours stay as shot (a Display P3 or Adobe RGB profile) and the camera, date and place
/// are kept.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct Metadata {
    /// The embedded ICC colour profile.
    pub icc_profile: Option<Vec<u8>>,
    /// The EXIF block (TIFF-structured, without the JPEG `Exif\0\0` prefix), its orientation
    /// tag reset to "upright" as the pixels read are upright.
    pub exif: Option<Vec<u8>>,
    /// Whether the EXIF orientation turned the pixels a quarter (a phone held upright): the
    /// camera then read the picture out column by column, not row by row (see
    /// [`Unshear::read_by_columns`](crate::Unshear::read_by_columns)). Read only: nothing of it
    /// is written.
    pub turned: bool,
}

/// Whether an ICC profile describes pixels of `img`'s kind: its colour space (bytes 16..20 of
/// the header) must be `RGB ` for a colour image and `GRAY` for a grey one. A CMYK photo's
/// profile, for instance, does not describe the RGB pixels it was converted to.
fn profile_fits(profile: &[u8], img: &DynamicImage) -> bool {
    let want: &[u8] = if is_gray(img) { b"GRAY" } else { b"RGB " };
    profile.get(16..20) == Some(want)
}

/// Share of an image's rows from which [`missing_data_warning`] reports a bottom without data:
/// half a picture of it is no photo.
pub(crate) const MISSING_ROWS_SHARE: f64 = 0.5;

/// The row period [`missing_data_warning`] looks for: a JPEG decoder fills what a damaged file
/// lacks by repeating its last blocks (or one flat value), so the rows repeat every 8 or 16
/// (one MCU), which a photo's rows never do exactly over half the picture.
pub(crate) const MISSING_ROWS_PERIOD: usize = 16;

/// A warning when the bottom [`MISSING_ROWS_SHARE`] or more of `img`'s rows each repeat the
/// row [`MISSING_ROWS_PERIOD`] above exactly, as a decoder leaves the rows a damaged file has
/// no data for (image-rs fills them and reports success; a JPEG whose header declared 308x56826
/// pixels but held the data of a 320x243 photo decoded 99.5% of its rows so): what is measured
/// in such an image is only its top. `None` otherwise, and for images under 32 rows.
pub(crate) fn missing_data_warning(img: &DynamicImage) -> Option<String> {
    let h = img.height() as usize;
    let bytes = img.as_bytes();
    if h < 2 * MISSING_ROWS_PERIOD || bytes.is_empty() {
        return None;
    }
    let row = bytes.len() / h;
    let at = |y: usize| &bytes[y * row..(y + 1) * row];
    let repeated = (MISSING_ROWS_PERIOD..h)
        .rev()
        .take_while(|&y| at(y) == at(y - MISSING_ROWS_PERIOD))
        .count();
    let share = repeated as f64 / h as f64;
    (share >= MISSING_ROWS_SHARE).then(|| {
        format!(
            "the bottom {:.0}% of the rows ({repeated} of {h}) repeat without data, as a decoder fills what a damaged file lacks: only the top was measured",
            share * 100.0
        )
    })
}

/// The reason [`write_image_atomic`] gives when the output exists and may not be replaced
/// ([`WriteOptions::overwrite`]).
pub const EXISTS: &str = "it exists and replacing it was not asked for";

/// How [`write_image_atomic`] may write.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriteOptions {
    /// Replace an existing output file (never an input, see `protected`).
    pub overwrite: bool,
    /// Files that must never be written, whatever `overwrite` says (the inputs).
    pub protected: Vec<PathBuf>,
    /// JPEG quality, 1..=100 (values outside are clamped).
    pub jpeg_quality: u8,
    /// Colour profile and EXIF block to write with the image, where the format stores them
    /// (profile: JPEG, PNG, TIFF, WebP; EXIF: JPEG, PNG, WebP). A profile of another colour
    /// space than the written pixels' is left out.
    pub metadata: Metadata,
}

impl Default for WriteOptions {
    fn default() -> Self {
        Self {
            overwrite: false,
            protected: Vec::new(),
            jpeg_quality: 95,
            metadata: Metadata::default(),
        }
    }
}

/// The output formats, chosen by extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum OutFormat {
    Jpeg,
    Png,
    /// `.pgm`: grey only.
    Pgm,
    /// `.ppm`: RGB only.
    Ppm,
    /// `.pnm`: PGM for grey images, PPM otherwise.
    Pnm,
    Bmp,
    Tiff,
    WebP,
}

fn out_format(path: &Path) -> Option<OutFormat> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    Some(match ext.as_str() {
        "jpg" | "jpeg" => OutFormat::Jpeg,
        "png" => OutFormat::Png,
        "pgm" => OutFormat::Pgm,
        "ppm" => OutFormat::Ppm,
        "pnm" => OutFormat::Pnm,
        "bmp" => OutFormat::Bmp,
        "tif" | "tiff" => OutFormat::Tiff,
        "webp" => OutFormat::WebP,
        _ => return None,
    })
}

/// Whether [`write_image_atomic`] can write to `path`, judged by its extension: `jpg`/`jpeg`,
/// `png`, `pgm`, `ppm`, `pnm`, `bmp`, `tif`/`tiff`, `webp` (case-insensitive). PBM is readable
/// but not offered as an output: it is 1-bit and would destroy a photo.
pub fn output_format_supported(path: &Path) -> bool {
    out_format(path).is_some()
}

fn is_gray(img: &DynamicImage) -> bool {
    !img.color().has_color()
}

/// Convert `img` to something `format` can store, changing as little as possible:
///
/// * JPEG: no alpha and 8-bit only → `L8` (grey) or `Rgb8`.
/// * PNG: everything up to 16 bits is kept; float → 16-bit.
/// * PGM: `L8` (colour is converted to luma); PPM: `Rgb8`; PNM: PGM for grey, else PPM (the
///   `image` PNM encoder writes 8-bit samples only).
/// * WebP (lossless): 8-bit, alpha kept. BMP: 8-bit, alpha kept; grey with alpha as `Rgba8`
///   (the BMP encoder drops a grey image's alpha).
/// * TIFF: everything kept except grey float (→ 16-bit grey); grey with alpha is stored as
///   `Rgba8`/`Rgba16` (the TIFF encoder has no grey-with-alpha).
///
/// Borrows `img` when it can be written as it is (no copy of a large photo just to encode it).
fn convert_for(img: &DynamicImage, format: OutFormat) -> Cow<'_, DynamicImage> {
    use DynamicImage as D;
    let gray = is_gray(img);
    let alpha = img.color().has_alpha();
    let keep = |ok: bool, conv: fn(&D) -> D| {
        if ok {
            Cow::Borrowed(img)
        } else {
            Cow::Owned(conv(img))
        }
    };
    match format {
        OutFormat::Jpeg => match (gray, img) {
            (true, D::ImageLuma8(_)) | (false, D::ImageRgb8(_)) => Cow::Borrowed(img),
            (true, _) => Cow::Owned(D::ImageLuma8(img.to_luma8())),
            (false, _) => Cow::Owned(D::ImageRgb8(img.to_rgb8())),
        },
        OutFormat::Png => match img {
            D::ImageRgb32F(_) => Cow::Owned(D::ImageRgb16(img.to_rgb16())),
            D::ImageRgba32F(_) => Cow::Owned(D::ImageRgba16(img.to_rgba16())),
            _ => Cow::Borrowed(img),
        },
        OutFormat::Pgm => keep(matches!(img, D::ImageLuma8(_)), |i| {
            D::ImageLuma8(i.to_luma8())
        }),
        OutFormat::Ppm => keep(matches!(img, D::ImageRgb8(_)), |i| {
            D::ImageRgb8(i.to_rgb8())
        }),
        OutFormat::Pnm if gray => convert_for(img, OutFormat::Pgm),
        OutFormat::Pnm => convert_for(img, OutFormat::Ppm),
        OutFormat::Bmp | OutFormat::WebP => match (gray, alpha) {
            (true, false) => keep(matches!(img, D::ImageLuma8(_)), |i| {
                D::ImageLuma8(i.to_luma8())
            }),
            (true, true) if format == OutFormat::WebP => {
                keep(matches!(img, D::ImageLumaA8(_)), |i| {
                    D::ImageLumaA8(i.to_luma_alpha8())
                })
            }
            (_, true) => keep(matches!(img, D::ImageRgba8(_)), |i| {
                D::ImageRgba8(i.to_rgba8())
            }),
            (false, false) => keep(matches!(img, D::ImageRgb8(_)), |i| {
                D::ImageRgb8(i.to_rgb8())
            }),
        },
        OutFormat::Tiff => match img {
            D::ImageLumaA8(_) => Cow::Owned(D::ImageRgba8(img.to_rgba8())),
            D::ImageLumaA16(_) => Cow::Owned(D::ImageRgba16(img.to_rgba16())),
            D::ImageLuma8(_)
            | D::ImageRgb8(_)
            | D::ImageRgba8(_)
            | D::ImageLuma16(_)
            | D::ImageRgb16(_)
            | D::ImageRgba16(_)
            | D::ImageRgb32F(_)
            | D::ImageRgba32F(_) => Cow::Borrowed(img),
            _ => Cow::Owned(D::ImageRgba32F(img.to_rgba32f())),
        },
    }
}

fn encode<W: Write + Seek>(
    img: &DynamicImage,
    format: OutFormat,
    opts: &WriteOptions,
    w: &mut W,
) -> image::ImageResult<()> {
    use image::codecs::{bmp::BmpEncoder, png::PngEncoder, tiff::TiffEncoder, webp::WebPEncoder};
    let img = convert_for(img, format);
    let meta = &opts.metadata;
    match format {
        OutFormat::Jpeg => {
            let quality = opts.jpeg_quality.clamp(1, 100);
            write_with_metadata(&img, JpegEncoder::new_with_quality(w, quality), meta)
        }
        OutFormat::Png => write_with_metadata(&img, PngEncoder::new(w), meta),
        OutFormat::Bmp => img.write_with_encoder(BmpEncoder::new(w)),
        OutFormat::Tiff => write_with_metadata(&img, TiffEncoder::new(w), meta),
        OutFormat::WebP => write_with_metadata(&img, WebPEncoder::new_lossless(w), meta),
        OutFormat::Pgm | OutFormat::Ppm | OutFormat::Pnm => {
            let subtype = if is_gray(&img) {
                PnmSubtype::Graymap(SampleEncoding::Binary)
            } else {
                PnmSubtype::Pixmap(SampleEncoding::Binary)
            };
            img.write_with_encoder(PnmEncoder::new(w).with_subtype(subtype))
        }
    }
}

/// Encodes `img` with `encoder`, handing it the profile (when it fits the pixels,
/// [`profile_fits`]) and the EXIF block of `meta`; what the format cannot store is left out.
fn write_with_metadata(
    img: &DynamicImage,
    mut encoder: impl image::ImageEncoder,
    meta: &Metadata,
) -> image::ImageResult<()> {
    if let Some(p) = meta.icc_profile.as_ref().filter(|p| profile_fits(p, img)) {
        // Unsupported by the format: the image is still written, without it.
        let _ = encoder.set_icc_profile(p.clone());
    }
    if let Some(x) = &meta.exif {
        let _ = encoder.set_exif_metadata(x.clone());
    }
    img.write_with_encoder(encoder)
}

/// `img` encoded in memory as [`write_image_atomic`] would write it to a file named `name`
/// (the format from its extension, the same conversions, `opts.metadata` kept where the format
/// stores it); nothing touches the file system, so `opts.overwrite` and `opts.protected` play
/// no part.
///
/// # Errors
/// [`Error::Refused`] for an unsupported extension, [`Error::Image`] if encoding fails.
pub fn encode_image(img: &DynamicImage, name: &Path, opts: &WriteOptions) -> Result<Vec<u8>> {
    let format = out_format(name).ok_or_else(|| unknown_format(name))?;
    let mut out = Cursor::new(Vec::new());
    encode(img, format, opts, &mut out).map_err(|source| Error::Image {
        path: name.to_path_buf(),
        source,
    })?;
    Ok(out.into_inner())
}

/// The refusal of an output name whose extension names no format written.
fn unknown_format(path: &Path) -> Error {
    Error::Refused {
        path: path.to_path_buf(),
        reason: "unknown output format (use .jpg, .png, .pgm, .ppm, .pnm, .bmp, .tif or .webp)"
            .to_owned(),
    }
}

/// Whether `a` and `b` name the same existing file: equal canonical paths, or (on Unix) the same
/// device and inode, which also catches hard links.
fn same_file(a: &Path, b: &Path) -> bool {
    if let (Ok(ca), Ok(cb)) = (a.canonicalize(), b.canonicalize()) {
        if ca == cb {
            return true;
        }
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return ma.dev() == mb.dev() && ma.ino() == mb.ino();
        }
    }
    false
}

/// Write `img` to `path` atomically, in the format named by the extension (see
/// [`output_format_supported`]; channels are converted only where the format needs it: JPEG and
/// PNM drop alpha, formats without 16-bit samples get 8-bit, PGM gets luma).
///
/// The data goes to a temporary `.unshear-*.tmp` file in the same folder, is flushed and synced,
/// then renamed over `path` — without replacing an existing file unless `opts.overwrite`. On any
/// error the temporary file is removed.
///
/// # Errors
/// [`Error::Refused`] if `path` is one of `opts.protected` (even with `overwrite`), or exists and
/// `overwrite` is false, or has an unsupported extension; [`Error::Image`] if encoding fails;
/// [`Error::Io`] for file-system errors.
pub fn write_image_atomic(img: &DynamicImage, path: &Path, opts: WriteOptions) -> Result<()> {
    let format = out_format(path).ok_or_else(|| unknown_format(path))?;
    write_atomic(path, &opts, |w| {
        encode(img, format, &opts, w).map_err(|source| Error::Image {
            path: path.to_path_buf(),
            source,
        })
    })
}

/// Writes whatever `write` produces to `path` atomically, with the same guarantees as
/// [`write_image_atomic`]: never over a protected input, never over an existing file unless
/// `opts.overwrite`, a temporary file in the same folder renamed into place, nothing left behind
/// on error.
pub fn write_atomic(
    path: &Path,
    opts: &WriteOptions,
    write: impl FnOnce(&mut BufWriter<&std::fs::File>) -> Result<()>,
) -> Result<()> {
    let refuse = |reason: &str| Error::Refused {
        path: path.to_path_buf(),
        reason: reason.to_owned(),
    };
    let io_err = |source| Error::Io {
        path: path.to_path_buf(),
        source,
    };
    check_writable(path, opts)?;
    let dir = folder_of(path);
    let mut builder = tempfile::Builder::new();
    builder.prefix(".unshear-").suffix(".tmp");
    // tempfile creates 0600 files; an output should get the usual 0666-minus-umask instead.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    // Listed while it exists, so a signal handler can remove it (see abandon_writes).
    let (tmp, _listed) = InProgress::create(&builder, dir).map_err(io_err)?;
    {
        let mut w = BufWriter::new(tmp.as_file());
        write(&mut w)?;
        w.flush().map_err(io_err)?;
    }
    tmp.as_file().sync_all().map_err(io_err)?;
    if opts.overwrite {
        tmp.persist(path).map_err(|e| io_err(e.error))?;
    } else {
        // The check above is racy; persist_noclobber makes "never replace" hold for real.
        tmp.persist_noclobber(path).map_err(|e| {
            if e.error.kind() == std::io::ErrorKind::AlreadyExists {
                refuse(EXISTS)
            } else {
                io_err(e.error)
            }
        })?;
    }
    Ok(())
}

/// Temporary files that [`write_atomic`] has created and not yet renamed or removed; `None`
/// once [`abandon_writes`] has run.
static IN_PROGRESS: std::sync::Mutex<Option<Vec<PathBuf>>> =
    std::sync::Mutex::new(Some(Vec::new()));

/// Refuses (with [`Error::Refused`]) to write `path` when it is one of `opts.protected`, or
/// exists and `opts.overwrite` is not set.
pub(crate) fn check_writable(path: &Path, opts: &WriteOptions) -> Result<()> {
    let refuse = |reason: &str| Error::Refused {
        path: path.to_path_buf(),
        reason: reason.to_owned(),
    };
    if opts.protected.iter().any(|p| same_file(p, path)) {
        return Err(refuse("it is an input file"));
    }
    if !opts.overwrite && path.exists() {
        return Err(refuse(EXISTS));
    }
    Ok(())
}

/// The folder `path` is in (`.` for a bare name).
pub(crate) fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// Keeps one temporary file (or folder) listed in [`IN_PROGRESS`] for its lifetime.
#[derive(Debug)]
pub(crate) struct InProgress(PathBuf);

impl InProgress {
    /// Creates the temporary file and lists it, under the lock, so that [`abandon_writes`] sees
    /// every file created before it and none can be created after it.
    fn create(
        builder: &tempfile::Builder,
        dir: &Path,
    ) -> std::io::Result<(tempfile::NamedTempFile, Self)> {
        Self::listing(|| builder.tempfile_in(dir), |t| t.path())
    }

    /// A new empty folder `.unshear-XXXXXX` in `parent`, listed as [`Self::create`] lists a
    /// file ([`abandon_writes`] removes it with its contents); the folder itself is removed
    /// when the returned `TempDir` is dropped.
    pub(crate) fn create_dir(parent: &Path) -> std::io::Result<(tempfile::TempDir, Self)> {
        let builder = tempfile::Builder::new().prefix(".unshear-").clone();
        Self::listing(|| builder.tempdir_in(parent), |t| t.path())
    }

    /// Makes something temporary with `make` and lists its `path`, under the lock.
    fn listing<T>(
        make: impl FnOnce() -> std::io::Result<T>,
        path: impl FnOnce(&T) -> &Path,
    ) -> std::io::Result<(T, Self)> {
        let mut list = IN_PROGRESS
            .lock()
            .map_err(|_| std::io::Error::other("a writer thread panicked"))?;
        let Some(list) = list.as_mut() else {
            return Err(std::io::Error::new(
                std::io::ErrorKind::Interrupted,
                "the process is stopping",
            ));
        };
        let made = make()?;
        let listed = path(&made).to_path_buf();
        list.push(listed.clone());
        Ok((made, Self(listed)))
    }
}

impl Drop for InProgress {
    fn drop(&mut self) {
        if let Ok(mut list) = IN_PROGRESS.lock() {
            if let Some(list) = list.as_mut() {
                if let Some(i) = list.iter().position(|p| *p == self.0) {
                    list.swap_remove(i);
                }
            }
        }
    }
}

/// For a process about to exit without unwinding (a signal handler, where the writing threads'
/// destructors will not run): removes the temporary files (`.unshear-*.tmp`) of the writes in
/// progress in this process, and makes every later write fail with
/// [`std::io::ErrorKind::Interrupted`] before it creates a file. Returns how many files were
/// removed.
///
/// Outputs are unaffected: a temporary file becomes an output only by an atomic rename, and
/// removing one whose rename has just happened fails harmlessly (the complete output stays).
pub fn abandon_writes() -> usize {
    let Ok(mut list) = IN_PROGRESS.lock() else {
        return 0;
    };
    list.take()
        .unwrap_or_default()
        .into_iter()
        .filter(|p| std::fs::remove_file(p).is_ok() || std::fs::remove_dir_all(p).is_ok())
        .count()
}

#[cfg(test)]
/// Tests of reading and writing. Each uses its own temporary folder.
mod tests {
    use super::*;
    use image::GrayImage;
    use image::{GenericImageView, ImageBuffer, Luma, LumaA, Rgb, RgbImage, Rgba};

    fn smooth(x: u32, y: u32, c: u32) -> u8 {
        (128.0 + 100.0 * ((x as f64 + 3.0 * c as f64) / 9.0).sin() * ((y as f64) / 13.0).cos())
            as u8
    }

    fn test_images() -> Vec<DynamicImage> {
        let (w, h) = (37, 23);
        vec![
            DynamicImage::ImageLuma8(ImageBuffer::from_fn(w, h, |x, y| Luma([smooth(x, y, 0)]))),
            DynamicImage::ImageRgb8(ImageBuffer::from_fn(w, h, |x, y| {
                Rgb([smooth(x, y, 0), smooth(x, y, 1), smooth(x, y, 2)])
            })),
            DynamicImage::ImageRgba8(ImageBuffer::from_fn(w, h, |x, y| {
                Rgba([
                    smooth(x, y, 0),
                    smooth(x, y, 1),
                    smooth(x, y, 2),
                    (x * 7) as u8,
                ])
            })),
        ]
    }

    fn temp_files_left(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(".unshear-"))
            .collect()
    }

    #[test]
    fn every_format_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        for (i, img) in test_images().iter().enumerate() {
            for ext in [
                "png", "pgm", "ppm", "pnm", "bmp", "tif", "tiff", "webp", "jpg", "jpeg", "PNG",
            ] {
                let path = dir.path().join(format!("out{i}.{ext}"));
                assert!(output_format_supported(&path));
                write_image_atomic(img, &path, WriteOptions::default())
                    .unwrap_or_else(|e| panic!("{ext} {:?}: {e}", img.color()));
                let back = read_image(&path, DEFAULT_MAX_PIXELS).unwrap();
                assert_eq!(back.dimensions(), img.dimensions(), "{ext}");
                let format = out_format(&path).unwrap();
                let expected = convert_for(img, format).to_rgba8();
                let got = back.to_rgba8();
                if format == OutFormat::Jpeg {
                    // Lossy: quality 95 on smooth content stays within a few levels.
                    let diffs: Vec<u8> = expected
                        .as_raw()
                        .iter()
                        .zip(got.as_raw())
                        .map(|(a, b)| a.abs_diff(*b))
                        .collect();
                    let mean =
                        diffs.iter().map(|&d| f64::from(d)).sum::<f64>() / diffs.len() as f64;
                    let max = diffs.iter().copied().max().unwrap();
                    assert!(
                        mean < 2.0 && max < 20,
                        "{ext} {:?}: mean {mean} max {max}",
                        img.color()
                    );
                    assert!(!back.color().has_alpha());
                } else {
                    assert_eq!(expected, got, "{ext} {:?}", img.color());
                }
                // Alpha survives where the format has it.
                if matches!(
                    format,
                    OutFormat::Png | OutFormat::Tiff | OutFormat::WebP | OutFormat::Bmp
                ) {
                    assert_eq!(back.color().has_alpha(), img.color().has_alpha(), "{ext}");
                }
            }
        }
        assert!(temp_files_left(dir.path()).is_empty());
    }

    #[test]
    fn sixteen_bit_is_kept_where_possible() {
        let dir = tempfile::tempdir().unwrap();
        let img = DynamicImage::ImageLuma16(ImageBuffer::from_fn(20, 10, |x, y| {
            Luma([(x * 3000 + y * 7) as u16])
        }));
        for ext in ["png", "tif"] {
            let path = dir.path().join(format!("deep.{ext}"));
            write_image_atomic(&img, &path, WriteOptions::default()).unwrap();
            assert_eq!(read_image(&path, DEFAULT_MAX_PIXELS).unwrap(), img, "{ext}");
        }
        // PGM is written 8-bit.
        let path = dir.path().join("deep.pgm");
        write_image_atomic(&img, &path, WriteOptions::default()).unwrap();
        assert_eq!(
            read_image(&path, DEFAULT_MAX_PIXELS).unwrap(),
            DynamicImage::ImageLuma8(img.to_luma8())
        );
        // 16-bit grey with alpha to a format without 16 bits: 8-bit grey with alpha.
        let la = DynamicImage::ImageLumaA16(ImageBuffer::from_fn(4, 4, |x, _| {
            LumaA([(x * 20000) as u16, 65535])
        }));
        let path = dir.path().join("la.webp");
        write_image_atomic(&la, &path, WriteOptions::default()).unwrap();
        assert_eq!(
            read_image(&path, DEFAULT_MAX_PIXELS)
                .unwrap()
                .to_luma_alpha8(),
            la.to_luma_alpha8()
        );
    }

    /// Grey-with-alpha TIFFs, which the `image` crate refuses, are read with both channels
    /// exact; too large, they are refused as such. The fixtures are FFmpeg's TIFFs (PackBits,
    /// `ExtraSamples` = unassociated alpha) of raw `ya8` / `ya16le` samples: grey `16 x + y` /
    /// `4096 x + y`, alpha `255 - 8 x` / `65535 - 2048 x`.
    #[test]
    fn grey_alpha_tiffs_are_read() {
        let eight = include_bytes!("../tests/fixtures/grey-alpha-8x6.tiff");
        let DynamicImage::ImageLumaA8(img) = read_image_from_memory(eight, 1 << 20).unwrap() else {
            panic!("not 8-bit grey with alpha");
        };
        assert_eq!(img.dimensions(), (8, 6));
        for (x, y, p) in img.enumerate_pixels() {
            assert_eq!(p.0, [(16 * x + y) as u8, (255 - 8 * x) as u8], "({x}, {y})");
        }
        let sixteen = include_bytes!("../tests/fixtures/grey-alpha16-8x6.tiff");
        let DynamicImage::ImageLumaA16(img) = read_image_from_memory(sixteen, 1 << 20).unwrap()
        else {
            panic!("not 16-bit grey with alpha");
        };
        for (x, y, p) in img.enumerate_pixels() {
            assert_eq!(
                p.0,
                [(4096 * x + y) as u16, (65535 - 2048 * x) as u16],
                "({x}, {y})"
            );
        }
        assert!(matches!(
            read_image_from_memory(eight, 47),
            Err(Error::TooLarge { pixels: 48, .. })
        ));
    }

    #[test]
    fn grey_with_alpha_keeps_its_alpha_in_tiff_and_bmp() {
        let dir = tempfile::tempdir().unwrap();
        let la = DynamicImage::ImageLumaA8(ImageBuffer::from_fn(4, 4, |x, y| {
            LumaA([(x * 60) as u8, (y * 80) as u8])
        }));
        for ext in ["tif", "bmp"] {
            let path = dir.path().join(format!("la.{ext}"));
            write_image_atomic(&la, &path, WriteOptions::default()).unwrap();
            let back = read_image(&path, DEFAULT_MAX_PIXELS).unwrap();
            assert_eq!(back.to_luma_alpha8(), la.to_luma_alpha8(), "{ext}");
        }
    }

    /// A JPEG with an EXIF APP1 segment carrying `orientation`, inserted right after SOI.
    fn jpeg_with_orientation(img: &RgbImage, orientation: u8) -> Vec<u8> {
        let mut jpeg = Vec::new();
        JpegEncoder::new_with_quality(&mut jpeg, 95)
            .encode_image(img)
            .unwrap();
        let mut tiff = b"MM\x00\x2a\x00\x00\x00\x08".to_vec(); // big-endian TIFF header, IFD at 8
        tiff.extend_from_slice(&[0, 1]); // one entry
        tiff.extend_from_slice(&[0x01, 0x12, 0, 3, 0, 0, 0, 1, 0, orientation, 0, 0]); // Orientation, SHORT
        tiff.extend_from_slice(&[0, 0, 0, 0]); // no next IFD
        let mut app1 = vec![0xff, 0xe1];
        let len = (2 + 6 + tiff.len()) as u16;
        app1.extend_from_slice(&len.to_be_bytes());
        app1.extend_from_slice(b"Exif\0\0");
        app1.extend_from_slice(&tiff);
        assert_eq!(&jpeg[..2], &[0xff, 0xd8]);
        jpeg.splice(2..2, app1);
        jpeg
    }

    #[test]
    fn exif_orientation_is_applied() {
        // 32x16: left half black, right half white.
        let img = RgbImage::from_fn(32, 16, |x, _| {
            if x < 16 {
                Rgb([0, 0, 0])
            } else {
                Rgb([255, 255, 255])
            }
        });
        let bright = |i: &DynamicImage, x, y| i.get_pixel(x, y)[0] > 200;
        let dark = |i: &DynamicImage, x, y| i.get_pixel(x, y)[0] < 50;

        let plain =
            read_image_from_memory(&jpeg_with_orientation(&img, 1), DEFAULT_MAX_PIXELS).unwrap();
        assert_eq!(plain.dimensions(), (32, 16));
        assert!(dark(&plain, 4, 8) && bright(&plain, 28, 8));

        // 6: rotate 90 degrees clockwise to display: the left (black) half goes to the top.
        let r90 =
            read_image_from_memory(&jpeg_with_orientation(&img, 6), DEFAULT_MAX_PIXELS).unwrap();
        assert_eq!(r90.dimensions(), (16, 32));
        assert!(dark(&r90, 8, 4) && bright(&r90, 8, 28));

        // 3: rotate 180 degrees: black goes to the right.
        let r180 =
            read_image_from_memory(&jpeg_with_orientation(&img, 3), DEFAULT_MAX_PIXELS).unwrap();
        assert_eq!(r180.dimensions(), (32, 16));
        assert!(bright(&r180, 4, 8) && dark(&r180, 28, 8));

        // Through a file, too.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rotated.jpg");
        std::fs::write(&path, jpeg_with_orientation(&img, 6)).unwrap();
        assert_eq!(
            read_image(&path, DEFAULT_MAX_PIXELS).unwrap().dimensions(),
            (16, 32)
        );
    }

    #[test]
    fn quarter_turns_are_told_apart() {
        let img = RgbImage::from_fn(8, 4, |x, y| Rgb([smooth(x, y, 0), 0, 0]));
        let dir = tempfile::tempdir().unwrap();
        for orientation in 1..=8u8 {
            let path = dir.path().join(format!("{orientation}.jpg"));
            std::fs::write(&path, jpeg_with_orientation(&img, orientation)).unwrap();
            let (read, meta) = read_image_with_metadata(&path, DEFAULT_MAX_PIXELS).unwrap();
            // 5 to 8 transpose (turned a quarter, mirrored or not); 1 to 4 keep the axes.
            assert_eq!(meta.turned, orientation >= 5, "{orientation}");
            let turned_size = if orientation >= 5 { (4, 8) } else { (8, 4) };
            assert_eq!(read.dimensions(), turned_size, "{orientation}");
        }
    }

    /// A made-up ICC profile of colour space `space`: only its header is looked at here.
    fn fake_profile(space: &[u8; 4]) -> Vec<u8> {
        let mut p: Vec<u8> = (0..200u8).collect();
        p[16..20].copy_from_slice(space);
        p
    }

    #[test]
    fn profile_and_exif_are_carried_to_the_output_upright() {
        let img = RgbImage::from_fn(32, 16, |x, y| Rgb([smooth(x, y, 0), smooth(x, y, 1), 9]));
        let jpeg = jpeg_with_orientation(&img, 6);
        let (upright, meta) = {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("in.jpg");
            std::fs::write(&path, &jpeg).unwrap();
            read_image_with_metadata(&path, DEFAULT_MAX_PIXELS).unwrap()
        };
        assert_eq!(upright.dimensions(), (16, 32));
        assert!(meta.turned, "orientation 6 turns the picture a quarter");
        let exif = meta.exif.clone().expect("the EXIF block is read");
        assert_eq!(
            image::metadata::Orientation::from_exif_chunk(&exif),
            Some(image::metadata::Orientation::NoTransforms),
            "the orientation tag is reset, the pixels being upright"
        );
        let meta = Metadata {
            icc_profile: Some(fake_profile(b"RGB ")),
            ..meta
        };
        let dir = tempfile::tempdir().unwrap();
        for name in ["out.jpg", "out.png", "out.webp", "out.tif"] {
            let path = dir.path().join(name);
            let opts = WriteOptions {
                metadata: meta.clone(),
                ..WriteOptions::default()
            };
            let in_memory = encode_image(&upright, &path, &opts).unwrap();
            write_image_atomic(&upright, &path, opts).unwrap();
            let (back, read) = read_image_with_metadata(&path, DEFAULT_MAX_PIXELS).unwrap();
            assert_eq!(back.dimensions(), (16, 32), "{name}: not turned again");
            // In memory: the same bytes as the file, read back the same.
            assert_eq!(
                in_memory,
                std::fs::read(&path).unwrap(),
                "{name}: encode_image"
            );
            let (_, from_memory) =
                read_image_with_metadata_from_memory(&in_memory, DEFAULT_MAX_PIXELS).unwrap();
            assert_eq!(from_memory, read, "{name}: read from memory");
            if name == "out.tif" {
                // TIFF: the encoder stores the profile (checked with Pillow) but the decoder does
                // not read it back, and stores no EXIF block.
                continue;
            }
            assert_eq!(read.icc_profile, meta.icc_profile, "{name}: profile");
            assert_eq!(read.exif, meta.exif, "{name}: EXIF");
        }
        // Without metadata asked for, none is written.
        let path = dir.path().join("plain.jpg");
        write_image_atomic(&upright, &path, WriteOptions::default()).unwrap();
        let (_, none) = read_image_with_metadata(&path, DEFAULT_MAX_PIXELS).unwrap();
        assert_eq!(none, Metadata::default());
    }

    #[test]
    fn a_profile_of_other_pixels_is_left_out() {
        let rgb = DynamicImage::ImageRgb8(RgbImage::new(8, 8));
        let gray = DynamicImage::ImageLuma8(GrayImage::new(8, 8));
        assert!(profile_fits(&fake_profile(b"RGB "), &rgb));
        assert!(!profile_fits(&fake_profile(b"CMYK"), &rgb));
        assert!(!profile_fits(&fake_profile(b"RGB "), &gray));
        assert!(profile_fits(&fake_profile(b"GRAY"), &gray));
        assert!(!profile_fits(b"short", &rgb));
        // A CMYK photo's profile does not travel to its RGB output.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.png");
        let opts = WriteOptions {
            metadata: Metadata {
                icc_profile: Some(fake_profile(b"CMYK")),
                ..Metadata::default()
            },
            ..WriteOptions::default()
        };
        write_image_atomic(&rgb, &path, opts).unwrap();
        let (_, read) = read_image_with_metadata(&path, DEFAULT_MAX_PIXELS).unwrap();
        assert_eq!(read.icc_profile, None);
    }

    #[test]
    fn files_larger_than_any_image_within_the_limit_are_cut_off() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.pgm");
        // 100 pixels allow 800 bytes and the 16 MiB slack; this file has one byte more.
        let limit = max_file_bytes(100);
        std::fs::write(&path, vec![b'P'; limit as usize + 1]).unwrap();
        assert!(matches!(
            read_image(&path, 100),
            Err(Error::FileTooLarge { limit: l, .. }) if l == limit
        ));
        // A device without end is read only up to the limit.
        #[cfg(unix)]
        assert!(matches!(
            read_image(Path::new("/dev/zero"), 100),
            Err(Error::FileTooLarge { .. })
        ));
    }

    #[test]
    fn oversized_images_are_rejected_before_decoding() {
        // A binary PGM header that declares 100000 x 100000 pixels, followed by almost no data:
        // decoding would need 10 GB, so reaching the decoder would fail differently (or slowly).
        let mut pgm = b"P5\n100000 100000\n255\n".to_vec();
        pgm.extend_from_slice(&[0; 16]);
        match read_image_from_memory(&pgm, DEFAULT_MAX_PIXELS) {
            Err(Error::TooLarge {
                width,
                height,
                pixels,
                limit,
            }) => {
                assert_eq!(
                    (width, height, pixels, limit),
                    (100_000, 100_000, 10_000_000_000, DEFAULT_MAX_PIXELS)
                );
            }
            other => panic!("expected TooLarge, got {other:?}"),
        }
        // A PNG whose IHDR declares 100000 x 100000 RGB (valid CRCs), then an empty IDAT and IEND.
        let chunk = |kind: &[u8], data: &[u8]| {
            let mut body = kind.to_vec();
            body.extend_from_slice(data);
            let mut c = (data.len() as u32).to_be_bytes().to_vec();
            c.extend_from_slice(&body);
            c.extend_from_slice(&crc32(&body).to_be_bytes());
            c
        };
        let mut ihdr = 100_000u32.to_be_bytes().to_vec();
        ihdr.extend_from_slice(&100_000u32.to_be_bytes());
        ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        png.extend(chunk(b"IHDR", &ihdr));
        png.extend(chunk(b"IDAT", &[]));
        png.extend(chunk(b"IEND", &[]));
        assert!(
            matches!(
                read_image_from_memory(&png, DEFAULT_MAX_PIXELS),
                Err(Error::TooLarge {
                    width: 100_000,
                    height: 100_000,
                    ..
                })
            ),
            "{:?}",
            read_image_from_memory(&png, DEFAULT_MAX_PIXELS)
        );
        // A small real image over a small limit.
        let mut png = Vec::new();
        test_images()[0]
            .write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        assert!(matches!(
            read_image_from_memory(&png, 100),
            Err(Error::TooLarge { pixels: 851, .. })
        ));
        assert!(read_image_from_memory(&png, 851).is_ok());
    }

    /// CRC-32 (IEEE) as PNG chunks use it.
    fn crc32(data: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in data {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    #[test]
    fn a_decode_mostly_without_data_at_the_bottom_is_warned_about() {
        // A photo whose bottom `filled` rows repeat an 8-row block, as a decoder fills them.
        let photo = |filled: u32| {
            DynamicImage::ImageRgb8(image::RgbImage::from_fn(30, 80, |x, y| {
                let y = if y >= 80 - filled {
                    80 - filled + y % 8
                } else {
                    y
                };
                image::Rgb([(x * 7 + y) as u8, (y * 5) as u8, 9])
            }))
        };
        let w = missing_data_warning(&photo(60)).expect("three quarters filled");
        assert!(w.contains("of 80"), "{w}");
        assert!(missing_data_warning(&photo(60)).is_some());
        assert!(missing_data_warning(&photo(30)).is_none(), "under half");
        assert!(missing_data_warning(&photo(0)).is_none());
        // One flat value is a fill too; a picture under 32 rows says nothing.
        let flat = DynamicImage::ImageLuma8(GrayImage::new(10, 40));
        assert!(missing_data_warning(&flat).is_some());
        assert!(missing_data_warning(&DynamicImage::ImageLuma8(GrayImage::new(10, 31))).is_none());
    }

    #[test]
    fn truncated_jpeg_is_an_error_but_trailing_data_is_fine() {
        let img =
            DynamicImage::ImageRgb8(RgbImage::from_fn(32, 24, |x, y| Rgb([smooth(x, y, 0); 3])));
        let mut bytes = Vec::new();
        img.write_to(&mut Cursor::new(&mut bytes), image::ImageFormat::Jpeg)
            .expect("encode");
        assert!(read_image_from_memory(&bytes, DEFAULT_MAX_PIXELS).is_ok());
        let cut = &bytes[..bytes.len() - 10];
        let err = read_image_from_memory(cut, DEFAULT_MAX_PIXELS).expect_err("truncated");
        assert!(err.to_string().contains("truncated"), "{err}");
        let mut trailing = bytes.clone();
        trailing.extend_from_slice(b"camera trailer");
        assert!(read_image_from_memory(&trailing, DEFAULT_MAX_PIXELS).is_ok());
    }

    #[test]
    fn garbage_and_missing_files_are_errors() {
        assert!(matches!(
            read_image_from_memory(b"not an image at all", 1000),
            Err(Error::Image { .. })
        ));
        assert!(matches!(
            read_image_from_memory(b"\x89PNG\r\n\x1a\n\0\0", 1000),
            Err(Error::Image { .. })
        ));
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(
            read_image(&dir.path().join("missing.png"), 1000),
            Err(Error::Io { .. })
        ));
    }

    #[test]
    fn never_overwrites_an_input() {
        let dir = tempfile::tempdir().unwrap();
        let img = &test_images()[1];
        let input = dir.path().join("in.png");
        write_image_atomic(img, &input, WriteOptions::default()).unwrap();
        let before = std::fs::read(&input).unwrap();
        let other = DynamicImage::ImageRgb8(RgbImage::new(5, 5));
        let opts = WriteOptions {
            overwrite: true,
            protected: vec![input.clone()],
            ..WriteOptions::default()
        };
        // The same path, a different spelling of it, and (Unix) a hard link to it.
        let mut aliases = vec![input.clone(), dir.path().join(".").join("in.png")];
        #[cfg(unix)]
        {
            let link = dir.path().join("link.png");
            std::fs::hard_link(&input, &link).unwrap();
            aliases.push(link);
        }
        for alias in aliases {
            let err = write_image_atomic(&other, &alias, opts.clone()).unwrap_err();
            assert!(matches!(err, Error::Refused { .. }), "{alias:?}: {err}");
        }
        assert_eq!(std::fs::read(&input).unwrap(), before);
        assert!(temp_files_left(dir.path()).is_empty());
    }

    #[test]
    fn existing_output_needs_overwrite() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.png");
        let a = DynamicImage::ImageRgb8(RgbImage::from_pixel(3, 3, Rgb([1, 2, 3])));
        let b = DynamicImage::ImageRgb8(RgbImage::from_pixel(3, 3, Rgb([9, 8, 7])));
        write_image_atomic(&a, &path, WriteOptions::default()).unwrap();
        let err = write_image_atomic(&b, &path, WriteOptions::default()).unwrap_err();
        assert!(
            matches!(&err, Error::Refused { reason, .. } if reason == EXISTS),
            "{err}"
        );
        assert_eq!(read_image(&path, 100).unwrap(), a);
        write_image_atomic(
            &b,
            &path,
            WriteOptions {
                overwrite: true,
                ..WriteOptions::default()
            },
        )
        .unwrap();
        assert_eq!(read_image(&path, 100).unwrap(), b);
        assert!(temp_files_left(dir.path()).is_empty());
    }

    #[test]
    fn failures_leave_no_temp_files() {
        let dir = tempfile::tempdir().unwrap();
        let img = &test_images()[0];
        // Unknown extension.
        let path = dir.path().join("out.xyz");
        assert!(!output_format_supported(&path));
        assert!(matches!(
            write_image_atomic(img, &path, WriteOptions::default()),
            Err(Error::Refused { .. })
        ));
        assert!(!output_format_supported(Path::new("noext")));
        // Encoding failure (an empty image cannot be encoded as JPEG) after the temp file exists.
        let empty = DynamicImage::ImageRgb8(RgbImage::new(0, 0));
        let path = dir.path().join("empty.jpg");
        assert!(write_image_atomic(&empty, &path, WriteOptions::default()).is_err());
        assert!(!path.exists());
        // Missing folder.
        assert!(matches!(
            write_image_atomic(
                img,
                &dir.path().join("no/such/dir/x.png"),
                WriteOptions::default()
            ),
            Err(Error::Io { .. })
        ));
        assert!(temp_files_left(dir.path()).is_empty());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
