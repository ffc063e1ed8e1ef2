//! Folders of numbered frames (any format [`crate::imageio`] reads) in and out, and the y4m
//! reader and writer as frame sources and sinks.
//!
//! * In: every file of the folder (not its sub-folders) with an image extension, in natural
//!   order (`frame2.png` before `frame10.png`: runs of digits compare as numbers). All frames
//!   must have the size of the first.
//! * Out: `000000.EXT`, `000001.EXT`, ... in the output folder (created if needed). They are
//!   written into a temporary folder beside it and moved into it only when the run finishes,
//!   so a run that fails or is stopped leaves no frame; an existing file is only replaced
//!   when allowed, an input never.

use std::cmp::Ordering;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use super::color::{image_to_yuv, yuv_to_image};
use super::process::{FrameSink, FrameSource};
use super::y4m::{Y4mReader, Y4mWriter};
use super::VideoFrame;
use crate::imageio::{self, WriteOptions};
use crate::{Error, Result};

/// Extensions taken as frames when listing a folder (case-insensitive).
pub const FRAME_EXTENSIONS: &[&str] = &[
    "jpg", "jpeg", "png", "pgm", "ppm", "pnm", "bmp", "tif", "tiff", "webp",
];

/// Compares names so that runs of digits compare by value (`a2` < `a10`), then as text.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut x, mut y) = (a.as_bytes(), b.as_bytes());
    loop {
        match (x.first(), y.first()) {
            (None, None) => return a.cmp(b),
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(c), Some(d)) if c.is_ascii_digit() && d.is_ascii_digit() => {
                let nx = x.iter().take_while(|c| c.is_ascii_digit()).count();
                let ny = y.iter().take_while(|c| c.is_ascii_digit()).count();
                let (dx, dy) = (&x[..nx], &y[..ny]);
                // Compare by value: strip leading zeros, then longer is larger.
                let strip = |d: &'_ [u8]| -> usize { d.iter().take_while(|&&c| c == b'0').count() };
                let (vx, vy) = (&dx[strip(dx)..], &dy[strip(dy)..]);
                let o = vx.len().cmp(&vy.len()).then_with(|| vx.cmp(vy));
                if o != Ordering::Equal {
                    return o;
                }
                x = &x[nx..];
                y = &y[ny..];
            }
            (Some(c), Some(d)) => {
                if c != d {
                    return c.cmp(d);
                }
                x = &x[1..];
                y = &y[1..];
            }
        }
    }
}

/// The frame files of `dir` in natural order.
///
/// # Errors
/// [`Error::Io`] if the folder cannot be read, [`Error::Video`] if it holds no frame.
pub fn list_frames(dir: &Path) -> Result<Vec<PathBuf>> {
    let io = |source| Error::Io {
        path: dir.to_path_buf(),
        source,
    };
    let mut frames = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        let is_frame = path.is_file()
            && path
                .extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| FRAME_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
        if is_frame {
            frames.push(path);
        }
    }
    if frames.is_empty() {
        return Err(Error::Video(format!(
            "{}: no frames (image files) in the folder",
            dir.display()
        )));
    }
    frames.sort_by(|a, b| {
        let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
        natural_cmp(&name(a).unwrap_or_default(), &name(b).unwrap_or_default())
    });
    Ok(frames)
}

/// A file name split around the last run of digits of its stem: (text before, number, text
/// after); `None` without digits (or a number too long for `u64`).
fn numbered(path: &Path) -> Option<(String, u64, String)> {
    let name = path.file_name()?.to_string_lossy().into_owned();
    let stem_len = path
        .file_stem()
        .map_or(name.len(), |s| s.to_string_lossy().len());
    let stem = &name[..stem_len];
    let end = stem.rfind(|c: char| c.is_ascii_digit())? + 1;
    let start = stem[..end]
        .rfind(|c: char| !c.is_ascii_digit())
        .map_or(0, |i| i + 1);
    let number = stem[start..end].parse().ok()?;
    Some((name[..start].to_string(), number, name[end..].to_string()))
}

/// The gaps in the numbering of frame files in order (`000003.png` then `000007.png`): for
/// each, the names on both sides and how many numbers are missing. Only neighbours whose names
/// differ in their last number alone are compared.
pub fn frame_gaps(paths: &[PathBuf]) -> Vec<(String, String, u64)> {
    let name = |p: &Path| {
        p.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    paths
        .windows(2)
        .filter_map(|pair| {
            let (a, b) = (numbered(&pair[0])?, numbered(&pair[1])?);
            let same_pattern = a.0 == b.0 && a.2 == b.2;
            (same_pattern && b.1 > a.1 + 1).then(|| (name(&pair[0]), name(&pair[1]), b.1 - a.1 - 1))
        })
        .collect()
}

/// Frames read from a list of image files.
#[derive(Debug)]
pub struct FrameFolderReader {
    paths: Vec<PathBuf>,
    next: usize,
    max_pixels: u64,
    size: (u32, u32),
    first: Option<VideoFrame>,
}

impl FrameFolderReader {
    /// Reads the first frame (to know the size) of `paths`.
    ///
    /// # Errors
    /// [`Error::Video`] for an empty list; the first image's read error.
    pub fn new(paths: Vec<PathBuf>, max_pixels: u64) -> Result<Self> {
        let first_path = paths
            .first()
            .ok_or_else(|| Error::Video("no frames".into()))?;
        let first = imageio::read_image(first_path, max_pixels)?;
        Ok(Self {
            size: (first.width(), first.height()),
            first: Some(VideoFrame::Image(first)),
            next: 1,
            paths,
            max_pixels,
        })
    }

    /// Width and height of every frame.
    pub fn dimensions(&self) -> (u32, u32) {
        self.size
    }

    /// The input files.
    pub fn paths(&self) -> &[PathBuf] {
        &self.paths
    }
}

impl FrameSource for FrameFolderReader {
    fn next_frame(&mut self) -> Result<Option<VideoFrame>> {
        if let Some(f) = self.first.take() {
            return Ok(Some(f));
        }
        let Some(path) = self.paths.get(self.next) else {
            return Ok(None);
        };
        self.next += 1;
        let img = imageio::read_image(path, self.max_pixels)?;
        if (img.width(), img.height()) != self.size {
            return Err(Error::Video(format!(
                "{}: {}x{}, but the first frame is {}x{}",
                path.display(),
                img.width(),
                img.height(),
                self.size.0,
                self.size.1
            )));
        }
        Ok(Some(VideoFrame::Image(img)))
    }
}

/// Frames written as numbered images into a folder: staged in a temporary folder beside it
/// (`.unshear-XXXXXX`, so that moving them in is a rename) and moved in by
/// [`Self::commit`], after checking that none would replace an input, or an existing file
/// without `overwrite`. Dropped uncommitted (a run that failed, Ctrl-C), it leaves nothing:
/// [`run`](super::run) finishes a sink even when its source failed part-way, so committing
/// is the caller's decision.
#[derive(Debug)]
pub struct FrameFolderWriter {
    dir: PathBuf,
    extension: String,
    options: WriteOptions,
    next: u64,
    staging: tempfile::TempDir,
    _listed: imageio::InProgress,
}

impl FrameFolderWriter {
    /// Writes into `dir` (created when the frames are moved in, with the folders above it) as
    /// `NNNNNN.<extension>`.
    ///
    /// # Errors
    /// [`Error::Refused`] for an extension [`imageio`] cannot write, [`Error::Io`] if the
    /// folder above `dir` or the staging folder cannot be created.
    pub fn new(dir: &Path, extension: &str, options: WriteOptions) -> Result<Self> {
        let probe = dir.join(format!("000000.{extension}"));
        if !imageio::output_format_supported(&probe) {
            return Err(Error::Refused {
                path: probe,
                reason: "unknown frame format (use jpg, png, pgm, ppm, pnm, bmp, tif or webp)"
                    .into(),
            });
        }
        let io_err = |path: &Path| {
            let path = path.to_path_buf();
            move |source| Error::Io { path, source }
        };
        let parent = imageio::folder_of(dir);
        std::fs::create_dir_all(parent).map_err(io_err(parent))?;
        let (staging, listed) = imageio::InProgress::create_dir(parent).map_err(io_err(parent))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            extension: extension.to_string(),
            options,
            next: 0,
            staging,
            _listed: listed,
        })
    }

    /// The file frame `index` is written to (once the frames are moved in).
    pub fn frame_path(&self, index: u64) -> PathBuf {
        self.dir.join(self.frame_name(index))
    }

    fn frame_name(&self, index: u64) -> String {
        format!("{index:06}.{}", self.extension)
    }

    /// How many frames numbered past the last one written are in the folder (of an earlier,
    /// longer run replaced with `overwrite`): they are not removed, and make the folder read
    /// as a longer clip.
    pub fn later_frames(&self) -> u64 {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return 0;
        };
        let suffix = format!(".{}", self.extension);
        entries
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().into_string().ok()?;
                let digits = name.strip_suffix(&suffix)?;
                let index: u64 = (digits.len() == 6).then(|| digits.parse().ok())??;
                (index >= self.next).then_some(())
            })
            .count() as u64
    }
}

impl FrameSink for FrameFolderWriter {
    fn write_frame(&mut self, frame: VideoFrame) -> Result<()> {
        let img = match frame {
            VideoFrame::Image(i) => i,
            VideoFrame::Yuv(f) => yuv_to_image(&f),
            // Images are written at 8 bits.
            VideoFrame::Yuv16(f) => yuv_to_image(&f.to_8bit()),
        };
        let path = self.staging.path().join(self.frame_name(self.next));
        let options = WriteOptions {
            overwrite: false,
            protected: Vec::new(),
            ..self.options.clone()
        };
        imageio::write_image_atomic(&img, &path, options)?;
        self.next += 1;
        Ok(())
    }

    fn finish(&mut self) -> Result<()> {
        Ok(())
    }
}

impl FrameFolderWriter {
    /// Moves the frames written into the folder (created with the folders above it): none if
    /// one would replace an input, or an existing file without `overwrite`.
    ///
    /// # Errors
    /// [`Error::Refused`] for such a frame, [`Error::Io`] if a frame cannot be moved.
    pub fn commit(&mut self) -> Result<()> {
        let targets: Vec<PathBuf> = (0..self.next).map(|i| self.frame_path(i)).collect();
        for target in &targets {
            imageio::check_writable(target, &self.options)?;
        }
        std::fs::create_dir_all(&self.dir).map_err(|source| Error::Io {
            path: self.dir.clone(),
            source,
        })?;
        for (i, target) in targets.iter().enumerate() {
            let staged = self.staging.path().join(self.frame_name(i as u64));
            std::fs::rename(&staged, target).map_err(|source| Error::Io {
                path: target.clone(),
                source,
            })?;
        }
        Ok(())
    }
}

impl<R: Read + Send> FrameSource for Y4mReader<R> {
    fn next_frame(&mut self) -> Result<Option<VideoFrame>> {
        self.read_video_frame()
    }
}

impl<W: Write + Send> FrameSink for Y4mWriter<W> {
    fn write_frame(&mut self, frame: VideoFrame) -> Result<()> {
        match frame {
            VideoFrame::Image(i) => {
                let f = self.format();
                let yuv = image_to_yuv(&i, f.chroma, f.full_range);
                Y4mWriter::write_frame(self, &yuv)
            }
            yuv => self.write_video_frame(&yuv),
        }
    }

    fn finish(&mut self) -> Result<()> {
        self.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{DynamicImage, GrayImage, Luma};

    #[test]
    fn natural_order() {
        let mut v = vec!["f10.png", "f2.png", "f1.png", "f02.png", "g.png", "f.png"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            v,
            ["f.png", "f1.png", "f02.png", "f2.png", "f10.png", "g.png"]
        );
    }

    #[test]
    fn gaps_in_the_numbering() {
        let paths = |names: &[&str]| names.iter().map(PathBuf::from).collect::<Vec<_>>();
        assert_eq!(
            frame_gaps(&paths(&[
                "d/000001.png",
                "d/000002.png",
                "d/000003.png",
                "d/000007.png",
                "d/000008.png",
                "d/000010.png"
            ])),
            [
                ("000003.png".to_string(), "000007.png".to_string(), 3),
                ("000008.png".to_string(), "000010.png".to_string(), 1)
            ]
        );
        assert!(frame_gaps(&paths(&["f1.png", "f2.png", "f10.png", "g12.png"])).len() == 1);
        assert!(frame_gaps(&paths(&["a.png", "b.png", "c9.png"])).is_empty());
        assert!(frame_gaps(&paths(&["take2_0001.png", "take2_0002.png"])).is_empty());
    }

    #[test]
    fn folder_round_trip_and_size_check() {
        let dir = tempfile::tempdir().expect("temp dir");
        let input = dir.path().join("in");
        std::fs::create_dir(&input).expect("mkdir");
        for (i, v) in [(10, 50u8), (9, 40), (1, 30)] {
            let img = GrayImage::from_pixel(8, 6, Luma([v]));
            img.save(input.join(format!("frame{i}.png"))).expect("save");
        }
        std::fs::write(input.join("notes.txt"), b"x").expect("write");
        let paths = list_frames(&input).expect("frames");
        let names: Vec<_> = paths
            .iter()
            .map(|p| {
                p.file_name()
                    .unwrap_or_default()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        assert_eq!(names, ["frame1.png", "frame9.png", "frame10.png"]);
        let mut reader = FrameFolderReader::new(paths, 1000).expect("first frame");
        assert_eq!(reader.dimensions(), (8, 6));
        let out = dir.path().join("out");
        let mut writer =
            FrameFolderWriter::new(&out, "png", WriteOptions::default()).expect("writer");
        while let Some(f) = reader.next_frame().expect("frame") {
            writer.write_frame(f).expect("write");
        }
        // Nothing under the folder's name until the frames are moved in.
        assert!(!out.exists());
        writer.commit().expect("moved in");
        drop(writer);
        let back = imageio::read_image(&out.join("000002.png"), 1000).expect("written");
        assert_eq!(
            back,
            DynamicImage::ImageLuma8(GrayImage::from_pixel(8, 6, Luma([50])))
        );
        let staged = |d: &Path| {
            std::fs::read_dir(d)
                .expect("list")
                .filter(|e| {
                    let name = e.as_ref().expect("entry").file_name();
                    name.to_string_lossy().starts_with(".unshear-")
                })
                .count()
        };
        assert_eq!(staged(dir.path()), 0, "the staging folder is removed");
        // Existing outputs are not replaced without permission: no frame is moved in.
        let mut again =
            FrameFolderWriter::new(&out, "png", WriteOptions::default()).expect("writer");
        let frame = |v| {
            VideoFrame::Image(DynamicImage::ImageLuma8(GrayImage::from_pixel(
                8,
                6,
                Luma([v]),
            )))
        };
        again.write_frame(frame(7)).expect("staged");
        assert!(matches!(again.commit(), Err(Error::Refused { .. })));
        drop(again);
        assert_eq!(staged(dir.path()), 0);
        let first = imageio::read_image(&out.join("000000.png"), 1000).expect("kept");
        assert_ne!(first.to_luma8().get_pixel(0, 0)[0], 7);
        // Replaced with permission; the later frames of the longer run are counted.
        let options = WriteOptions {
            overwrite: true,
            ..WriteOptions::default()
        };
        let mut shorter = FrameFolderWriter::new(&out, "png", options).expect("writer");
        shorter.write_frame(frame(7)).expect("staged");
        shorter.commit().expect("moved in");
        assert_eq!(shorter.later_frames(), 2);
        let first = imageio::read_image(&out.join("000000.png"), 1000).expect("replaced");
        assert_eq!(first.to_luma8().get_pixel(0, 0)[0], 7);
        drop(shorter);
        // Dropped unfinished (an error part-way), it leaves nothing.
        let fresh = dir.path().join("fresh");
        let mut failed =
            FrameFolderWriter::new(&fresh, "png", WriteOptions::default()).expect("writer");
        failed.write_frame(frame(1)).expect("staged");
        drop(failed);
        assert!(!fresh.exists());
        assert_eq!(staged(dir.path()), 0);
        // A frame of another size is an error.
        GrayImage::new(4, 4)
            .save(input.join("frame11.png"))
            .expect("save");
        let mut reader =
            FrameFolderReader::new(list_frames(&input).expect("frames"), 1000).expect("first");
        let results: Vec<_> = std::iter::from_fn(|| reader.next_frame().transpose()).collect();
        assert!(results.last().is_some_and(|r| r.is_err()));
        assert!(list_frames(&out.join("nothing")).is_err());
    }
}
