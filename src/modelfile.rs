//! The binary layout the project's network files share (`models/landmarks.bin`,
//! `models/proposals.bin`): 8 magic bytes, a little-endian `u32` format version, a `u32` header
//! length, a JSON header, then the weights as little-endian `f32`. What the header holds, and
//! how many weights follow, is each network's own (`landmarks::net`, `detect::proposals`).

use serde::de::DeserializeOwned;

use crate::error::{Error, Result};

/// A network file being read: its header parsed, then its weights taken in order.
#[derive(Debug)]
pub(crate) struct ModelFile<'a> {
    bytes: &'a [u8],
    /// Where the next weight starts.
    at: usize,
}

fn read_u32(bytes: &[u8], at: usize) -> Result<u32> {
    bytes
        .get(at..at + 4)
        .and_then(|b| b.try_into().ok())
        .map(u32::from_le_bytes)
        .ok_or_else(|| Error::ModelFile("truncated header".into()))
}

impl<'a> ModelFile<'a> {
    /// Checks the magic and the version and parses the header; `what` names the kind of file in
    /// the error for a wrong magic ("a landmark network").
    pub(crate) fn open<H: DeserializeOwned>(
        bytes: &'a [u8],
        magic: &[u8; 8],
        version: u32,
        what: &str,
    ) -> Result<(H, Self)> {
        Self::open_versions(bytes, magic, &[version], what).map(|(h, _, f)| (h, f))
    }

    /// [`Self::open`] for a reader of several format versions: also returns the file's.
    pub(crate) fn open_versions<H: DeserializeOwned>(
        bytes: &'a [u8],
        magic: &[u8; 8],
        versions: &[u32],
        what: &str,
    ) -> Result<(H, u32, Self)> {
        if bytes.get(..8) != Some(magic.as_slice()) {
            return Err(Error::ModelFile(format!("not {what} (bad magic)")));
        }
        let found = read_u32(bytes, 8)?;
        if !versions.contains(&found) {
            return Err(Error::ModelFile(format!("unsupported version {found}")));
        }
        let header_end = (read_u32(bytes, 12)? as usize)
            .checked_add(16)
            .ok_or_else(|| Error::ModelFile("truncated header".into()))?;
        let header_bytes = bytes
            .get(16..header_end)
            .ok_or_else(|| Error::ModelFile("truncated header".into()))?;
        let header = serde_json::from_slice(header_bytes)
            .map_err(|e| Error::ModelFile(format!("header: {e}")))?;
        Ok((
            header,
            found,
            Self {
                bytes,
                at: header_end,
            },
        ))
    }

    /// The next `n` weights; an error if the file ends first or one is not finite.
    pub(crate) fn take(&mut self, n: usize) -> Result<Vec<f32>> {
        let end = n
            .checked_mul(4)
            .and_then(|len| self.at.checked_add(len))
            .ok_or_else(|| Error::ModelFile("truncated weights".into()))?;
        let raw = self
            .bytes
            .get(self.at..end)
            .ok_or_else(|| Error::ModelFile("truncated weights".into()))?;
        self.at = end;
        let values: Vec<f32> = raw
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        if values.iter().all(|v| v.is_finite()) {
            Ok(values)
        } else {
            Err(Error::ModelFile("a weight is not finite".into()))
        }
    }

    /// An error if bytes are left after the weights taken.
    pub(crate) fn finish(self) -> Result<()> {
        match self.bytes.len() - self.at {
            0 => Ok(()),
            left => Err(Error::ModelFile(format!(
                "{left} bytes after the last layer"
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize, PartialEq)]
    struct Header {
        n: usize,
    }

    fn file(magic: &[u8; 8], version: u32, header: &str, values: &[f32]) -> Vec<u8> {
        let mut bytes = magic.to_vec();
        bytes.extend(version.to_le_bytes());
        bytes.extend((header.len() as u32).to_le_bytes());
        bytes.extend(header.as_bytes());
        bytes.extend(values.iter().flat_map(|v| v.to_le_bytes()));
        bytes
    }

    #[test]
    fn a_file_reads_back_its_header_and_weights_and_nothing_else() {
        let bytes = file(b"UNSHEART", 3, r#"{"n": 3}"#, &[1.0, -2.5, 3.25, 4.0]);
        let (header, mut reader) =
            ModelFile::open::<Header>(&bytes, b"UNSHEART", 3, "a test file").expect("valid");
        assert_eq!(header, Header { n: 3 });
        assert_eq!(reader.take(3).expect("three"), vec![1.0, -2.5, 3.25]);
        // One value left over.
        let left = ModelFile::open::<Header>(&bytes, b"UNSHEART", 3, "x")
            .expect("valid")
            .1;
        assert!(left.finish().is_err());
        assert_eq!(reader.take(1).expect("the fourth"), vec![4.0]);
        assert!(reader.take(1).is_err(), "past the end");
    }

    #[test]
    fn wrong_magic_version_header_or_values_are_errors() {
        let good = file(b"UNSHEART", 1, r#"{"n": 1}"#, &[1.0]);
        fn open(b: &[u8]) -> Result<(Header, ModelFile<'_>)> {
            ModelFile::open::<Header>(b, b"UNSHEART", 1, "a test file")
        }
        assert!(open(&good).is_ok());
        let message = open(&file(b"UNSHEARX", 1, r#"{"n": 1}"#, &[1.0]))
            .expect_err("bad magic")
            .to_string();
        assert!(message.contains("not a test file"), "{message}");
        assert!(open(&file(b"UNSHEART", 2, r#"{"n": 1}"#, &[1.0])).is_err());
        assert!(open(&file(b"UNSHEART", 1, r#"{"m": 1}"#, &[1.0])).is_err());
        assert!(open(&good[..14]).is_err(), "cut in the header length");
        assert!(open(&good[..20]).is_err(), "cut in the header");
        let nan = file(b"UNSHEART", 1, r#"{"n": 1}"#, &[f32::NAN]);
        assert!(open(&nan).expect("header fine").1.take(1).is_err());
        assert!(open(&good).expect("valid").1.take(usize::MAX).is_err());
    }

    /// The trainers record their tool versions, seed and command in the header
    /// (`scripts/provenance.py`); keys a reader does not know must not make a file unreadable.
    #[test]
    fn header_keys_the_reader_does_not_know_are_ignored() {
        let header = r#"{"n": 1, "seed": 1, "versions": {"python": "3.11.7", "torch": "2.15.0"}}"#;
        let bytes = file(b"UNSHEART", 1, header, &[1.0]);
        let (header, mut reader) =
            ModelFile::open::<Header>(&bytes, b"UNSHEART", 1, "a test file").expect("valid");
        assert_eq!(header, Header { n: 1 });
        assert_eq!(reader.take(1).expect("one"), vec![1.0]);
    }
}
