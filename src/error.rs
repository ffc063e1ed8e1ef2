//! The library's typed errors. The binary adds file-name context with `anyhow`.

use std::path::PathBuf;

/// Everything the `unshear` library can fail with.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An image file could not be opened, decoded or encoded.
    #[error("{path}: {source}")]
    Image {
        /// The file concerned.
        path: PathBuf,
        /// What the `image` crate reported.
        #[source]
        source: image::ImageError,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// The operating-system error.
        #[source]
        source: std::io::Error,
    },
    /// The image is larger than the configured decoded-size limit.
    #[error("image is {width}x{height} = {pixels} pixels, over the limit of {limit} pixels")]
    TooLarge {
        /// Declared width.
        width: u32,
        /// Declared height.
        height: u32,
        /// width * height.
        pixels: u64,
        /// The limit in force.
        limit: u64,
    },
    /// A file holds more bytes than any image within the pixel limit can take
    /// (`crate::imageio::max_file_bytes`).
    #[error("{path}: more than {limit} bytes, larger than any image within the pixel limit")]
    FileTooLarge {
        /// The file concerned.
        path: PathBuf,
        /// The byte limit in force.
        limit: u64,
    },
    /// An OpenCV cascade XML file is malformed or uses something we do not support.
    #[error("cascade: {0}")]
    Cascade(String),
    /// A correlation-filter file is malformed, truncated or of an unknown version.
    #[error("filter file: {0}")]
    FilterFile(String),
    /// A filter file names a filter type this build does not know (codes 1-3 are UMACE, ASEF,
    /// MOSSE).
    #[error("filter file: unknown filter type code {0}")]
    UnknownFilterType(u32),
    /// A landmark-network file is malformed, truncated, of an unknown version or does not match
    /// the network's topology.
    #[error("landmark network file: {0}")]
    ModelFile(String),
    /// A training data set is missing, malformed or too small.
    #[error("training data: {0}")]
    Training(String),
    /// An argument is outside its valid range (for example a non-finite shear).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// A video stream or frame folder is malformed, truncated, inconsistent or in a layout that
    /// is not supported (see [`crate::video`]).
    #[error("video: {0}")]
    Video(String),
    /// The output would overwrite an input or an existing file.
    #[error("refusing to write {path}: {reason}")]
    Refused {
        /// The output path.
        path: PathBuf,
        /// Why it was refused.
        reason: String,
    },
}

/// Result with the library's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
