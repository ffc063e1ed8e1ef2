//! The eye-filter file: a small versioned binary format, loaded with validation.
//!
//! Layout (all integers and floats little-endian):
//!
//! | bytes | field |
//! |---|---|
//! | 8 | magic `UNSHEARF` |
//! | 4 | format version, `2` (`1` is still read) |
//! | 4 | filter type: `1` = UMACE, `2` = ASEF, `3` = MOSSE ([`FilterType::code`]) |
//! | 4 | side `n` of each square filter (8 to 256) |
//! | 4 | face width the filters were trained at, pixels (150) |
//! | 4 | number of filters: `3` (the subject's right eye, the left eye, the nose) or `4` (and the mouth) |
//! | per filter: 4 + 8 n^2 | training-patch count, then `n * n` complex spectrum values as (re, im) `f32` pairs, row-major |
//! | 8 | FNV-1a 64-bit hash of every byte before it |
//!
//! Writing the same filters gives the same bytes, so a retrained file can be compared with the
//! committed one byte for byte.
//!
//! **Versions.** Version 1 had the same layout but only type 1; it is read as UMACE, and a
//! version-1 file naming another type is rejected. Version 2 admits ASEF and MOSSE, and marks
//! filters trained on OpenCV-weighted grey (the grey the detector and the locator see at run
//! time, [`crate::detect::to_gray_opencv`]); version-1 filters were trained on Rec. 709 grey.
//! An unknown type code is [`Error::UnknownFilterType`]. This build writes version 2.

use std::path::Path;

use rustfft::num_complex::Complex32;

use super::{Filter, FilterType};
use crate::error::{Error, Result};

const MAGIC: &[u8; 8] = b"UNSHEARF";
/// The file-format version this build writes (it also reads version 1, as UMACE).
pub(crate) const FORMAT_VERSION: u32 = 2;
const MIN_SIZE: usize = 8;
/// Filters in a file without a mouth filter: right eye, left eye, nose.
const FILTER_COUNT_NO_MOUTH: u32 = 3;
/// Filters in a file with a mouth filter.
const FILTER_COUNT_WITH_MOUTH: u32 = 4;
const MAX_SIZE: usize = 256;

/// The built-in filter sets, one per type (trained with `unshear train --filter-type T`, see
/// `models/README.md`).
static EMBEDDED_UMACE: &[u8] = include_bytes!("../../models/eye_filters_umace.bin");
static EMBEDDED_ASEF: &[u8] = include_bytes!("../../models/eye_filters_asef.bin");
static EMBEDDED_MOSSE: &[u8] = include_bytes!("../../models/eye_filters_mosse.bin");

/// The filter set: one filter for each eye, as the paper, one for the nose and (optionally) one
/// for the mouth.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct EyeFilters {
    /// Filter for the subject's right eye (on the image's left).
    pub right_eye: Filter,
    /// Filter for the subject's left eye (on the image's right); also used for the nostrils.
    pub left_eye: Filter,
    /// Filter for the whole lower nose (tip and both nostrils), centred on the annotated nose
    /// point: used to find where the nose is before the nostrils are searched for.
    pub nose: Filter,
    /// Filter for the mouth, centred on the annotated mouth centre: the mouth gives a second,
    /// longer face axis that yaw moves less than the nose (see [`crate::estimate`]). Files
    /// without it still load; the estimate then uses the nose alone.
    pub mouth: Option<Filter>,
    /// Width of the normalised face the filters were trained at, in pixels.
    pub face_width: u32,
    /// How the filters were synthesised (stored in the file).
    pub kind: FilterType,
}

impl EyeFilters {
    /// The built-in filters of the default type, [`FilterType::DEFAULT`].
    pub fn embedded() -> Result<Self> {
        Self::builtin(FilterType::DEFAULT)
    }

    /// The built-in filters of type `kind`.
    pub fn builtin(kind: FilterType) -> Result<Self> {
        let bytes = match kind {
            FilterType::Umace => EMBEDDED_UMACE,
            FilterType::Asef => EMBEDDED_ASEF,
            FilterType::Mosse => EMBEDDED_MOSSE,
        };
        let filters = Self::from_bytes(bytes)?;
        if filters.kind != kind {
            return Err(Error::FilterFile(format!(
                "built-in {kind} filters are of type {}",
                filters.kind
            )));
        }
        Ok(filters)
    }

    /// Side length of the filters.
    pub fn size(&self) -> usize {
        self.right_eye.size
    }

    /// Reads and validates a filter file.
    pub fn from_file(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(&bytes)
    }

    /// Parses and validates filter-file bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let bad = |m: &str| Error::FilterFile(m.to_string());
        if bytes.len() < 8 + 5 * 4 + 8 {
            return Err(bad("file too short for the header"));
        }
        if &bytes[..8] != MAGIC {
            return Err(bad("not an unshear filter file (bad magic)"));
        }
        let (body, tail) = bytes.split_at(bytes.len() - 8);
        let stored_hash =
            u64::from_le_bytes(tail.try_into().map_err(|_| bad("truncated checksum"))?);
        if fnv1a(body) != stored_hash {
            return Err(bad("checksum mismatch (file corrupt or truncated)"));
        }
        let mut r = Reader {
            bytes: body,
            pos: 8,
        };
        let version = r.u32()?;
        if !(1..=FORMAT_VERSION).contains(&version) {
            return Err(Error::FilterFile(format!(
                "format version {version} not supported (this build reads 1 to {FORMAT_VERSION})"
            )));
        }
        let kind = FilterType::from_code(r.u32()?)?;
        if version == 1 && kind != FilterType::Umace {
            return Err(Error::FilterFile(format!(
                "format version 1 holds UMACE filters only, not {kind}"
            )));
        }
        let size = r.u32()? as usize;
        if !(MIN_SIZE..=MAX_SIZE).contains(&size) {
            return Err(Error::FilterFile(format!(
                "filter size {size} outside {MIN_SIZE}..={MAX_SIZE}"
            )));
        }
        let face_width = r.u32()?;
        if !(16..=4096).contains(&face_width) {
            return Err(Error::FilterFile(format!(
                "implausible face width {face_width}"
            )));
        }
        let count = r.u32()?;
        if count != FILTER_COUNT_NO_MOUTH && count != FILTER_COUNT_WITH_MOUTH {
            return Err(Error::FilterFile(format!(
                "expected {FILTER_COUNT_NO_MOUTH} or {FILTER_COUNT_WITH_MOUTH} filters, found {count}"
            )));
        }
        let expected = 8 + 5 * 4 + count as usize * (4 + 8 * size * size);
        if body.len() != expected {
            return Err(Error::FilterFile(format!(
                "length {} does not match the header (expected {expected})",
                body.len()
            )));
        }
        let right_eye = r.filter(size)?;
        let left_eye = r.filter(size)?;
        let nose = r.filter(size)?;
        let mouth = if count == FILTER_COUNT_WITH_MOUTH {
            Some(r.filter(size)?)
        } else {
            None
        };
        Ok(Self {
            right_eye,
            left_eye,
            nose,
            mouth,
            face_width,
            kind,
        })
    }

    /// Serialises to the file format (deterministic).
    pub fn to_bytes(&self) -> Vec<u8> {
        let size = self.size();
        let filters: Vec<&Filter> = [&self.right_eye, &self.left_eye, &self.nose]
            .into_iter()
            .chain(self.mouth.as_ref())
            .collect();
        let mut out = Vec::with_capacity(8 + 5 * 4 + filters.len() * (4 + 8 * size * size) + 8);
        out.extend_from_slice(MAGIC);
        for v in [
            FORMAT_VERSION,
            self.kind.code(),
            size as u32,
            self.face_width,
            filters.len() as u32,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for f in filters {
            out.extend_from_slice(&f.training_count.to_le_bytes());
            for c in &f.spectrum {
                out.extend_from_slice(&c.re.to_le_bytes());
                out.extend_from_slice(&c.im.to_le_bytes());
            }
        }
        let hash = fnv1a(&out);
        out.extend_from_slice(&hash.to_le_bytes());
        out
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N]> {
        let end = self.pos + N;
        let slice = self
            .bytes
            .get(self.pos..end)
            .ok_or_else(|| Error::FilterFile("unexpected end of file".into()))?;
        self.pos = end;
        slice
            .try_into()
            .map_err(|_| Error::FilterFile("unexpected end of file".into()))
    }

    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take::<4>()?))
    }

    fn f32(&mut self) -> Result<f32> {
        let v = f32::from_le_bytes(self.take::<4>()?);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(Error::FilterFile("non-finite filter coefficient".into()))
        }
    }

    fn filter(&mut self, size: usize) -> Result<Filter> {
        let training_count = self.u32()?;
        let mut spectrum = Vec::with_capacity(size * size);
        for _ in 0..size * size {
            let re = self.f32()?;
            let im = self.f32()?;
            spectrum.push(Complex32::new(re, im));
        }
        Ok(Filter {
            size,
            spectrum,
            training_count,
        })
    }
}

/// FNV-1a, 64-bit: a few lines, enough to catch truncation and bit rot in a 64 KiB file
/// (not a defence against deliberate tampering, which the format does not claim).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(size: usize) -> EyeFilters {
        sample_of(size, FilterType::Umace)
    }

    fn sample_of(size: usize, kind: FilterType) -> EyeFilters {
        let f = |seed: f32| Filter {
            size,
            spectrum: (0..size * size)
                .map(|i| Complex32::new(i as f32 * 0.5 + seed, -(i as f32) + seed))
                .collect(),
            training_count: 7,
        };
        EyeFilters {
            right_eye: f(1.0),
            left_eye: f(2.0),
            nose: f(3.0),
            mouth: Some(f(4.0)),
            face_width: 150,
            kind,
        }
    }

    /// Re-seals `body` (a whole file) with a fresh checksum after editing it.
    fn reseal(mut body: Vec<u8>) -> Vec<u8> {
        body.truncate(body.len() - 8);
        let h = fnv1a(&body);
        body.extend_from_slice(&h.to_le_bytes());
        body
    }

    #[test]
    fn round_trip_keeps_the_type() {
        for kind in FilterType::ALL {
            let filters = sample_of(8, kind);
            let bytes = filters.to_bytes();
            assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().expect("4")), 2);
            assert_eq!(
                u32::from_le_bytes(bytes[12..16].try_into().expect("4")),
                kind.code()
            );
            let back = EyeFilters::from_bytes(&bytes).expect("valid");
            assert_eq!(back, filters);
            assert_eq!(bytes, back.to_bytes());
        }
    }

    /// Version-1 files (the layout before filter types) are read as UMACE; a version-1 file
    /// naming another type is refused.
    #[test]
    fn version_1_is_read_as_umace() {
        let mut v1 = sample(8).to_bytes();
        v1[8..12].copy_from_slice(&1u32.to_le_bytes());
        let f = EyeFilters::from_bytes(&reseal(v1.clone())).expect("v1 valid");
        assert_eq!(f.kind, FilterType::Umace);
        assert_eq!(f.right_eye, sample(8).right_eye);
        v1[12..16].copy_from_slice(&FilterType::Mosse.code().to_le_bytes());
        assert!(matches!(
            EyeFilters::from_bytes(&reseal(v1)),
            Err(Error::FilterFile(m)) if m.contains("version 1")
        ));
    }

    #[test]
    fn unknown_type_is_a_typed_error() {
        for code in [0u32, 4, 77] {
            let mut b = sample(8).to_bytes();
            b[12..16].copy_from_slice(&code.to_le_bytes());
            assert!(
                matches!(EyeFilters::from_bytes(&reseal(b)), Err(Error::UnknownFilterType(c)) if c == code),
                "code {code}"
            );
        }
    }

    #[test]
    fn files_without_a_mouth_filter_still_load() {
        let mut filters = sample(8);
        filters.mouth = None;
        let bytes = filters.to_bytes();
        assert_eq!(bytes.len(), sample(8).to_bytes().len() - (4 + 8 * 64));
        assert_eq!(EyeFilters::from_bytes(&bytes).expect("valid"), filters);
    }

    #[test]
    fn embedded_filters_load() {
        for kind in FilterType::ALL {
            let f = EyeFilters::builtin(kind).expect("embedded filters valid");
            assert_eq!(f.kind, kind);
            assert_eq!(f.size(), 64);
            assert_eq!(f.face_width, 150);
            assert!(f.right_eye.training_count >= 1500 && f.left_eye.training_count >= 1500);
            assert_eq!(f.nose.training_count, f.left_eye.training_count);
            let mouth = f.mouth.expect("built-in filters have a mouth filter");
            assert_eq!(mouth.training_count, f.left_eye.training_count);
        }
        assert_eq!(
            EyeFilters::embedded().expect("default").kind,
            FilterType::DEFAULT
        );
    }

    #[test]
    fn corrupt_files_are_rejected() {
        let good = sample(8).to_bytes();
        assert!(EyeFilters::from_bytes(&[]).is_err());
        assert!(EyeFilters::from_bytes(&good[..good.len() - 1]).is_err());
        let mut flipped = good.clone();
        flipped[40] ^= 1;
        assert!(
            matches!(EyeFilters::from_bytes(&flipped), Err(Error::FilterFile(m)) if m.contains("checksum"))
        );
        let mut magic = good.clone();
        magic[0] = b'X';
        assert!(EyeFilters::from_bytes(&magic).is_err());
    }

    /// A file with a valid checksum but a lying header is still rejected.
    #[test]
    fn inconsistent_header_is_rejected() {
        let good = sample(8).to_bytes();
        for (offset, value) in [
            (8, 0u32),
            (8, 3),
            (12, 9),
            (16, 4096),
            (16, 16),
            (24, 2),
            (24, 5),
            (20, 1),
        ] {
            let mut b = good.clone();
            b[offset..offset + 4].copy_from_slice(&value.to_le_bytes());
            assert!(
                EyeFilters::from_bytes(&reseal(b)).is_err(),
                "offset {offset} value {value}"
            );
        }
        let mut nan = good.clone();
        nan[40..44].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(EyeFilters::from_bytes(&reseal(nan)).is_err());
    }
}
