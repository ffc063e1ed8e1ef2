//! YUV4MPEG2 (`.y4m`) streams: what `ffmpeg -f yuv4mpegpipe` writes and reads.
//!
//! Reading goes through the `y4m` crate. Its header parser multiplies the declared width and
//! height without overflow checks and allocates the frame buffer before any frame arrives, so
//! the header line is first read and checked here (at most 1024 bytes, as the crate allows;
//! width and height positive and their product within the caller's pixel limit; a layout this
//! module supports) and only then handed, with the rest of the stream, to the crate. A stream
//! that ends inside a frame is reported as truncated (the crate would call it a clean end).
//!
//! 10- and 12-bit streams (`C420p10`, `C422p10`, `C444p10`, their `p12` kin and `Cmono12`, as
//! `ffmpeg -strict -1 -f yuv4mpegpipe` writes them) hold two bytes a sample, little-endian,
//! the value in the low bits; they are read into [`YuvFrame<u16>`] and written back the same
//! way ([`Y4mReader::read_frame16`], [`Y4mWriter::write_frame16`]).
//!
//! Writing puts out the input's own header line, unchanged (so interlacing, aspect, vendor
//! `X` tags and the colour tag survive and an unmodified stream round-trips byte for byte), or
//! one made by the crate's `EncoderBuilder` for frames that came from images. Frames are written
//! here rather than by the crate's encoder, which can only follow a header of its own making.

use std::io::{Chain, Cursor, Read, Write};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use image::GrayImage;

use super::{Chroma, Plane, VideoFormat, VideoFrame, YuvFrame};
use crate::{Error, Result};

/// The longest header line accepted (the `y4m` crate's own limit).
pub const MAX_HEADER_BYTES: usize = 1024;

const MAGIC: &[u8] = b"YUV4MPEG2 ";

fn video_err(msg: impl Into<String>) -> Error {
    Error::Video(msg.into())
}

/// Counts the bytes read through it (to tell a clean end of stream from a truncated frame).
/// The count is shared because the decoder takes ownership of the reader.
struct Counting<R> {
    inner: R,
    count: Arc<AtomicU64>,
}

impl<R: Read> Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count.fetch_add(n as u64, Ordering::Relaxed);
        Ok(n)
    }
}

/// Reads one header line (up to and including `\n`), byte by byte so nothing past it is
/// consumed.
fn read_header_line<R: Read>(reader: &mut R) -> Result<Vec<u8>> {
    let mut line = Vec::with_capacity(128);
    let mut byte = [0u8; 1];
    loop {
        let n = loop {
            match reader.read(&mut byte) {
                Ok(n) => break n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(video_err(format!("reading the y4m header: {e}"))),
            }
        };
        if n == 0 {
            return Err(video_err(if line.is_empty() {
                "empty input: no y4m header".to_string()
            } else {
                "the y4m header line has no end".to_string()
            }));
        }
        line.push(byte[0]);
        if byte[0] == b'\n' {
            return Ok(line);
        }
        if line.len() >= MAX_HEADER_BYTES {
            return Err(video_err(format!(
                "the y4m header is longer than {MAX_HEADER_BYTES} bytes"
            )));
        }
        if line.len() == MAGIC.len() && line != MAGIC {
            return Err(video_err(
                "not a y4m stream (it does not start with \"YUV4MPEG2 \")",
            ));
        }
    }
}

fn parse_u32(tag: &str, v: &[u8]) -> Result<u32> {
    std::str::from_utf8(v)
        .ok()
        .and_then(|s| s.parse::<u32>().ok())
        .ok_or_else(|| {
            video_err(format!(
                "y4m header: bad {tag} value {:?}",
                String::from_utf8_lossy(v)
            ))
        })
}

/// The format a header line declares, checked against `max_pixels`.
///
/// # Errors
/// [`Error::Video`] for a malformed header or an unsupported layout, [`Error::TooLarge`] when
/// `width * height > max_pixels`.
pub fn parse_header(line: &[u8], max_pixels: u64) -> Result<VideoFormat> {
    let body = line
        .strip_prefix(MAGIC)
        .ok_or_else(|| video_err("not a y4m stream (it does not start with \"YUV4MPEG2 \")"))?;
    let body = body.strip_suffix(b"\n").unwrap_or(body);
    let (mut width, mut height) = (None, None);
    let mut chroma = Chroma::Yuv420;
    let mut full_range = false;
    let mut frame_rate = (25, 1);
    let mut bit_depth = 8;
    for field in body.split(|&b| b == b' ').filter(|f| !f.is_empty()) {
        let (tag, value) = (field[0], &field[1..]);
        match tag {
            b'W' => width = Some(parse_u32("W", value)?),
            b'H' => height = Some(parse_u32("H", value)?),
            b'F' => {
                let mut parts = value.splitn(2, |&b| b == b':');
                let num = parse_u32("F", parts.next().unwrap_or_default())?;
                let den = parse_u32("F", parts.next().unwrap_or_default())?;
                frame_rate = (num, den);
            }
            b'C' => {
                (chroma, bit_depth) = match value {
                    b"420" | b"420jpeg" | b"420mpeg2" => (Chroma::Yuv420, 8),
                    b"420paldv" => (Chroma::Yuv420CoSited, 8),
                    b"422" => (Chroma::Yuv422, 8),
                    b"444" => (Chroma::Yuv444, 8),
                    b"mono" => (Chroma::Mono, 8),
                    b"420p10" => (Chroma::Yuv420, 10),
                    b"422p10" => (Chroma::Yuv422, 10),
                    b"444p10" => (Chroma::Yuv444, 10),
                    b"420p12" => (Chroma::Yuv420, 12),
                    b"422p12" => (Chroma::Yuv422, 12),
                    b"444p12" => (Chroma::Yuv444, 12),
                    b"mono12" => (Chroma::Mono, 12),
                    other => {
                        return Err(video_err(format!(
                            "y4m colour layout C{} is not supported (8-bit 420, 420jpeg, \
                             420mpeg2, 420paldv, 422, 444 and mono; 420p10, 422p10, 444p10, \
                             420p12, 422p12, 444p12 and mono12 are)",
                            String::from_utf8_lossy(other)
                        )))
                    }
                }
            }
            b'X' if value.eq_ignore_ascii_case(b"COLORRANGE=FULL") => full_range = true,
            _ => {}
        }
    }
    let (width, height) = match (width, height) {
        (Some(w), Some(h)) if w > 0 && h > 0 => (w, h),
        _ => return Err(video_err("y4m header: W and H must be given and positive")),
    };
    let pixels = u64::from(width) * u64::from(height);
    if pixels > max_pixels {
        return Err(Error::TooLarge {
            width,
            height,
            pixels,
            limit: max_pixels,
        });
    }
    Ok(VideoFormat {
        width,
        height,
        chroma,
        full_range,
        frame_rate,
        bit_depth,
    })
}

/// Reads YUV frames from a y4m stream (8-bit with [`Self::read_frame`], 10- and 12-bit with
/// [`Self::read_frame16`], either with [`Self::read_video_frame`]).
pub struct Y4mReader<R: Read> {
    decoder: y4m::Decoder<Counting<Chain<Cursor<Vec<u8>>, R>>>,
    format: VideoFormat,
    header: Vec<u8>,
    frames: u64,
    consumed: Arc<AtomicU64>,
}

impl<R: Read> Y4mReader<R> {
    /// Reads and checks the header (see the module docs). Give a buffered reader: the header
    /// is read a byte at a time.
    ///
    /// # Errors
    /// As [`parse_header`]; [`Error::Video`] when the stream cannot be read.
    pub fn new(mut reader: R, max_pixels: u64) -> Result<Self> {
        let header = read_header_line(&mut reader)?;
        let format = parse_header(&header, max_pixels)?;
        let frame_bytes = usize::try_from(format.frame_bytes())
            .map_err(|_| video_err("frame too large for this machine"))?;
        let consumed = Arc::new(AtomicU64::new(0));
        let stream = Counting {
            inner: Cursor::new(header.clone()).chain(reader),
            count: Arc::clone(&consumed),
        };
        let decoder = y4m::Decoder::new_with_limits(stream, y4m::Limits { bytes: frame_bytes })
            .map_err(|e| video_err(format!("y4m header: {e}")))?;
        if decoder.get_width() != format.width as usize
            || decoder.get_height() != format.height as usize
            || decoder.get_bit_depth() != format.bit_depth as usize
        {
            return Err(video_err("y4m header: inconsistent W, H or sample size"));
        }
        Ok(Self {
            decoder,
            format,
            header,
            frames: 0,
            consumed,
        })
    }

    /// The stream's format.
    pub fn format(&self) -> &VideoFormat {
        &self.format
    }

    /// The header line exactly as read, `\n` included.
    pub fn header(&self) -> &[u8] {
        &self.header
    }

    /// The next 8-bit frame, `None` at the end of the stream.
    ///
    /// # Errors
    /// [`Error::Video`] for a malformed frame header, a stream that ends inside a frame, a read
    /// error, or a stream of more than 8 bits (use [`Self::read_frame16`]).
    pub fn read_frame(&mut self) -> Result<Option<YuvFrame>> {
        if self.format.bit_depth != 8 {
            return Err(video_err(format!(
                "a {}-bit stream read as 8-bit (use read_frame16)",
                self.format.bit_depth
            )));
        }
        self.read_with(|data, w, h| {
            GrayImage::from_raw(w, h, data.to_vec())
                .ok_or_else(|| video_err("y4m frame: plane size mismatch"))
        })
    }

    /// The next 10- or 12-bit frame (little-endian samples), `None` at the end of the stream.
    ///
    /// # Errors
    /// As [`Self::read_frame`]; an 8-bit stream is an error here.
    pub fn read_frame16(&mut self) -> Result<Option<YuvFrame<u16>>> {
        if self.format.bit_depth <= 8 {
            return Err(video_err("an 8-bit stream read as 16-bit (use read_frame)"));
        }
        self.read_with(|data, w, h| {
            let samples = data
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect();
            Plane::from_raw(w, h, samples)
                .ok_or_else(|| video_err("y4m frame: plane size mismatch"))
        })
    }

    /// The next frame at the stream's depth ([`VideoFrame::Yuv`] or [`VideoFrame::Yuv16`]).
    ///
    /// # Errors
    /// As [`Self::read_frame`].
    pub fn read_video_frame(&mut self) -> Result<Option<VideoFrame>> {
        Ok(if self.format.bit_depth > 8 {
            self.read_frame16()?.map(VideoFrame::Yuv16)
        } else {
            self.read_frame()?.map(VideoFrame::Yuv)
        })
    }

    /// Reads one frame and makes its planes with `plane(bytes, width, height)`.
    fn read_with<T: super::YuvSample>(
        &mut self,
        plane: impl Fn(&[u8], u32, u32) -> Result<Plane<T>>,
    ) -> Result<Option<YuvFrame<T>>> {
        let before = self.decoder_count();
        match self.decoder.read_frame() {
            Ok(frame) => {
                let (w, h) = (self.format.width, self.format.height);
                let (cw, ch) = self.format.chroma.plane_size(w, h);
                let out = YuvFrame {
                    chroma: self.format.chroma,
                    full_range: self.format.full_range,
                    bit_depth: self.format.bit_depth,
                    y: plane(frame.get_y_plane(), w, h)?,
                    u: plane(frame.get_u_plane(), cw, ch)?,
                    v: plane(frame.get_v_plane(), cw, ch)?,
                    params: frame.get_raw_params().map(<[u8]>::to_vec),
                };
                self.frames += 1;
                Ok(Some(out))
            }
            Err(y4m::Error::EOF) if self.consumed.load(Ordering::Relaxed) == before => Ok(None),
            Err(y4m::Error::EOF) => Err(video_err(format!(
                "the stream ends inside frame {} (truncated)",
                self.frames
            ))),
            Err(e) => Err(video_err(format!("y4m frame {}: {e}", self.frames))),
        }
    }

    fn decoder_count(&self) -> u64 {
        self.consumed.load(Ordering::Relaxed)
    }
}

/// Writes YUV frames as a y4m stream (8-bit with [`Self::write_frame`], 10- and 12-bit with
/// [`Self::write_frame16`]).
pub struct Y4mWriter<W: Write> {
    writer: W,
    format: VideoFormat,
}

impl<W: Write> Y4mWriter<W> {
    /// A stream that starts with `header` (a whole header line, e.g. [`Y4mReader::header`]).
    ///
    /// # Errors
    /// [`Error::Video`] if the header is not a valid, supported y4m header or cannot be
    /// written.
    pub fn with_header(mut writer: W, header: &[u8]) -> Result<Self> {
        let format = parse_header(header, u64::MAX)?;
        if !header.ends_with(b"\n") {
            return Err(video_err("a y4m header line must end with a newline"));
        }
        writer
            .write_all(header)
            .map_err(|e| video_err(format!("writing the y4m header: {e}")))?;
        Ok(Self { writer, format })
    }

    /// A stream for frames of `format`, with a header made by the `y4m` crate (`C420jpeg` for
    /// 4:2:0, `C420paldv` for co-sited 4:2:0, `C420p10` and the like above 8 bits,
    /// `XCOLORRANGE=FULL` for full range).
    ///
    /// # Errors
    /// [`Error::Video`] if the format has no y4m layout (e.g. 10-bit mono or co-sited 4:2:0)
    /// or the header cannot be written.
    pub fn new(writer: W, format: &VideoFormat) -> Result<Self> {
        use y4m::Colorspace as C;
        let colorspace = match (format.chroma, format.bit_depth) {
            (Chroma::Mono, 8) => C::Cmono,
            (Chroma::Yuv420, 8) => C::C420jpeg,
            (Chroma::Yuv420CoSited, 8) => C::C420paldv,
            (Chroma::Yuv422, 8) => C::C422,
            (Chroma::Yuv444, 8) => C::C444,
            (Chroma::Yuv420, 10) => C::C420p10,
            (Chroma::Yuv422, 10) => C::C422p10,
            (Chroma::Yuv444, 10) => C::C444p10,
            (Chroma::Yuv420, 12) => C::C420p12,
            (Chroma::Yuv422, 12) => C::C422p12,
            (Chroma::Yuv444, 12) => C::C444p12,
            (Chroma::Mono, 12) => C::Cmono12,
            (chroma, depth) => {
                return Err(video_err(format!(
                    "no y4m layout for {depth}-bit {chroma:?}"
                )))
            }
        };
        let (num, den) = format.frame_rate;
        let mut builder = y4m::EncoderBuilder::new(
            format.width as usize,
            format.height as usize,
            y4m::Ratio::new(num as usize, den as usize),
        )
        .with_colorspace(colorspace);
        if format.full_range {
            let ext = y4m::VendorExtensionString::new(b"COLORRANGE=FULL".to_vec())
                .map_err(|e| video_err(e.to_string()))?;
            builder = builder.append_vendor_extension(ext);
        }
        let mut header = Vec::new();
        builder
            .write_header(&mut header)
            .map_err(|e| video_err(format!("y4m header: {e}")))?;
        Self::with_header(writer, &header)
    }

    /// The format every frame must have.
    pub fn format(&self) -> &VideoFormat {
        &self.format
    }

    /// Writes one 8-bit frame (its `FRAME` parameters kept).
    ///
    /// # Errors
    /// [`Error::Video`] if the frame's layout, size or depth differs from the stream's, or
    /// writing fails.
    pub fn write_frame(&mut self, frame: &YuvFrame) -> Result<()> {
        self.check(frame)?;
        self.write_with(frame, |w, plane: &GrayImage| w.write_all(plane.as_raw()))
    }

    /// Writes one 10- or 12-bit frame (little-endian samples, `FRAME` parameters kept).
    ///
    /// # Errors
    /// As [`Self::write_frame`].
    pub fn write_frame16(&mut self, frame: &YuvFrame<u16>) -> Result<()> {
        self.check(frame)?;
        let mut bytes = Vec::new();
        self.write_with(frame, |w, plane: &Plane<u16>| {
            bytes.clear();
            bytes.extend(plane.as_raw().iter().flat_map(|v| v.to_le_bytes()));
            w.write_all(&bytes)
        })
    }

    /// Writes a frame of either depth.
    ///
    /// # Errors
    /// As [`Self::write_frame`]; an image frame is an error (convert it first).
    pub fn write_video_frame(&mut self, frame: &VideoFrame) -> Result<()> {
        match frame {
            VideoFrame::Yuv(f) => self.write_frame(f),
            VideoFrame::Yuv16(f) => self.write_frame16(f),
            VideoFrame::Image(_) => Err(video_err("an image frame in a y4m stream")),
        }
    }

    fn check<T: super::YuvSample>(&self, frame: &YuvFrame<T>) -> Result<()> {
        let f = &self.format;
        let (cw, ch) = f.chroma.plane_size(f.width, f.height);
        if frame.bit_depth != f.bit_depth {
            return Err(video_err(format!(
                "a {}-bit frame in a {}-bit stream",
                frame.bit_depth, f.bit_depth
            )));
        }
        if frame.chroma != f.chroma
            || frame.y.dimensions() != (f.width, f.height)
            || frame.u.dimensions() != (cw, ch)
            || frame.v.dimensions() != (cw, ch)
        {
            return Err(video_err(format!(
                "frame is {}x{} {:?}, the stream {}x{} {:?}",
                frame.y.width(),
                frame.y.height(),
                frame.chroma,
                f.width,
                f.height,
                f.chroma
            )));
        }
        Ok(())
    }

    fn write_with<T: super::YuvSample>(
        &mut self,
        frame: &YuvFrame<T>,
        mut plane: impl FnMut(&mut W, &Plane<T>) -> std::io::Result<()>,
    ) -> Result<()> {
        let w = &mut self.writer;
        let result = (|| {
            w.write_all(b"FRAME")?;
            if let Some(p) = &frame.params {
                w.write_all(b" ")?;
                w.write_all(p)?;
            }
            w.write_all(b"\n")?;
            plane(w, &frame.y)?;
            plane(w, &frame.u)?;
            plane(w, &frame.v)
        })();
        result.map_err(|e| video_err(format!("writing a y4m frame: {e}")))
    }

    /// Flushes the underlying writer.
    ///
    /// # Errors
    /// [`Error::Video`] if flushing fails.
    pub fn flush(&mut self) -> Result<()> {
        self.writer
            .flush()
            .map_err(|e| video_err(format!("writing the y4m stream: {e}")))
    }

    /// Flushes and returns the writer.
    ///
    /// # Errors
    /// [`Error::Video`] if flushing fails.
    pub fn finish(mut self) -> Result<W> {
        self.flush()?;
        Ok(self.writer)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4:2:0 stream of `frames` frames with distinct bytes, and its header.
    fn stream(header: &[u8], w: usize, h: usize, frames: usize) -> Vec<u8> {
        let size = w * h + 2 * w.div_ceil(2) * h.div_ceil(2);
        let mut s = header.to_vec();
        for f in 0..frames {
            s.extend_from_slice(if f == 1 { b"FRAME Ixyz\n" } else { b"FRAME\n" });
            s.extend((0..size).map(|i| ((i * 7 + f * 13) % 251) as u8));
        }
        s
    }

    const HEADER: &[u8] = b"YUV4MPEG2 W5 H3 F30000:1001 Ip A1:1 C420jpeg XYSCSS=420JPEG\n";

    #[test]
    fn reads_and_writes_back_byte_for_byte() {
        let input = stream(HEADER, 5, 3, 3);
        let mut r = Y4mReader::new(input.as_slice(), 1000).expect("valid stream");
        assert_eq!(r.format().width, 5);
        assert_eq!(r.format().chroma, Chroma::Yuv420);
        assert_eq!(r.format().frame_rate, (30000, 1001));
        let mut w = Y4mWriter::with_header(Vec::new(), r.header()).expect("header");
        let mut n = 0;
        while let Some(f) = r.read_frame().expect("frame") {
            assert_eq!(f.u.dimensions(), (3, 2));
            w.write_frame(&f).expect("write");
            n += 1;
        }
        assert_eq!(n, 3);
        assert_eq!(w.finish().expect("flush"), input);
    }

    #[test]
    fn truncated_frame_is_an_error_and_clean_end_is_not() {
        let input = stream(HEADER, 5, 3, 2);
        let mut r = Y4mReader::new(&input[..input.len() - 4], 1000).expect("header");
        assert!(r.read_frame().expect("first frame").is_some());
        let err = r.read_frame().expect_err("truncated");
        assert!(err.to_string().contains("truncated"), "{err}");
        let header_only = Y4mReader::new(HEADER, 1000)
            .expect("header")
            .read_frame()
            .expect("clean end");
        assert!(header_only.is_none());
    }

    #[test]
    fn bad_headers_are_refused_before_allocating() {
        let cases: [&[u8]; 8] = [
            b"",
            b"YUV4MPEG2 W5 H3",
            b"RIFF0000WAVEfmt \n",
            b"YUV4MPEG2 W0 H3 C420\n",
            b"YUV4MPEG2 W99999999999999999999 H3\n",
            b"YUV4MPEG2 W5 H3 C420p16\n",
            b"YUV4MPEG2 W5 H3 C411\n",
            b"YUV4MPEG2 W5 H3 Fx:1\n",
        ];
        for c in cases {
            assert!(
                matches!(Y4mReader::new(c, 1000), Err(Error::Video(_))),
                "{:?}",
                String::from_utf8_lossy(c)
            );
        }
        let huge = b"YUV4MPEG2 W4000000000 H4000000000 C444\n";
        assert!(matches!(
            Y4mReader::new(huge.as_slice(), 1 << 30),
            Err(Error::TooLarge { .. })
        ));
        let long = [MAGIC, &[b'X'; 2000][..], b"\n"].concat();
        assert!(Y4mReader::new(long.as_slice(), 1000).is_err());
    }

    #[test]
    fn bad_frame_header_is_an_error() {
        let mut input = stream(HEADER, 5, 3, 1);
        input.extend_from_slice(b"FRAMX\n");
        let mut r = Y4mReader::new(input.as_slice(), 1000).expect("header");
        assert!(r.read_frame().expect("frame 0").is_some());
        assert!(r.read_frame().is_err());
    }

    #[test]
    fn made_header_describes_the_format() {
        for (chroma, tag) in [
            (Chroma::Yuv420, "C420jpeg"),
            (Chroma::Yuv422, "C422"),
            (Chroma::Yuv444, "C444"),
            (Chroma::Mono, "Cmono"),
        ] {
            let format = VideoFormat {
                width: 6,
                height: 4,
                chroma,
                full_range: true,
                frame_rate: (25, 1),
                bit_depth: 8,
            };
            let w = Y4mWriter::new(Vec::new(), &format).expect("header");
            let bytes = w.finish().expect("flush");
            let text = String::from_utf8(bytes.clone()).expect("ascii");
            assert!(
                text.contains(tag) && text.contains("XCOLORRANGE=FULL"),
                "{text}"
            );
            assert_eq!(parse_header(&bytes, 100).expect("parses"), format);
        }
    }

    #[test]
    fn frame_of_another_size_is_refused() {
        let format = parse_header(HEADER, 100).expect("header");
        let mut w = Y4mWriter::with_header(Vec::new(), HEADER).expect("header");
        let mut f = YuvFrame::blank(&format);
        assert!(w.write_frame(&f).is_ok());
        f.y = GrayImage::new(4, 3);
        assert!(w.write_frame(&f).is_err());
    }

    #[test]
    fn ten_bit_streams_round_trip_at_their_depth() {
        // FFmpeg's header for yuv420p10le; samples little-endian in the low 10 bits.
        let header = b"YUV4MPEG2 W5 H3 F25:1 Ip A1:1 C420p10 XYSCSS=420P10 XCOLORRANGE=LIMITED\n";
        let samples = 5 * 3 + 2 * 3 * 2;
        let mut input = header.to_vec();
        for f in 0..2u16 {
            input.extend_from_slice(b"FRAME\n");
            input.extend(
                (0..samples as u16).flat_map(|i| ((i * 37 + f * 101) % 1024).to_le_bytes()),
            );
        }
        let mut r = Y4mReader::new(input.as_slice(), 1000).expect("10-bit header");
        assert_eq!(r.format().bit_depth, 10);
        assert_eq!(r.format().frame_bytes(), 2 * samples as u64);
        assert!(r.read_frame().is_err(), "8-bit read of a 10-bit stream");
        let mut r = Y4mReader::new(input.as_slice(), 1000).expect("10-bit header");
        let mut w = Y4mWriter::with_header(Vec::new(), r.header()).expect("header");
        let mut frames = 0;
        while let Some(f) = r.read_video_frame().expect("frame") {
            let VideoFrame::Yuv16(f) = f else {
                panic!("a 10-bit frame reads as Yuv16")
            };
            assert_eq!(f.bit_depth, 10);
            assert_eq!(f.y.get_pixel(1, 0)[0], 37 + frames * 101);
            assert_eq!(f.u.dimensions(), (3, 2));
            // An 8-bit frame does not go into a 10-bit stream.
            assert!(w.write_frame(&f.to_8bit()).is_err());
            w.write_frame16(&f).expect("write");
            frames += 1;
        }
        assert_eq!(frames, 2);
        assert_eq!(w.finish().expect("flush"), input);
        // Made headers name the depth.
        let format = parse_header(header, 100).expect("parses");
        let made = Y4mWriter::new(Vec::new(), &format)
            .expect("10-bit header")
            .finish()
            .expect("flush");
        assert!(String::from_utf8_lossy(&made).contains("C420p10"));
        assert_eq!(parse_header(&made, 100).expect("parses").bit_depth, 10);
    }
}
