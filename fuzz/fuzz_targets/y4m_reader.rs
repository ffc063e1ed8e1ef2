//! The y4m reader on arbitrary bytes, with a small pixel limit (so a header declaring a huge
//! frame is refused before anything is allocated): every frame it yields is written back with
//! the writer, and must read back as the same frames (8-bit and 10/12-bit streams alike).
#![no_main]

use libfuzzer_sys::fuzz_target;
use unshear::video::y4m::{Y4mReader, Y4mWriter};

fuzz_target!(|data: &[u8]| {
    let Ok(mut reader) = Y4mReader::new(data, 1 << 16) else {
        return;
    };
    let mut frames = Vec::new();
    while let Ok(Some(frame)) = reader.read_video_frame() {
        frames.push(frame);
        if frames.len() > 64 {
            break;
        }
    }
    let Ok(mut writer) = Y4mWriter::with_header(Vec::new(), reader.header()) else {
        return;
    };
    for f in &frames {
        if writer.write_video_frame(f).is_err() {
            return;
        }
    }
    let Ok(bytes) = writer.finish() else {
        return;
    };
    let mut again = Y4mReader::new(&bytes[..], 1 << 16).expect("written stream reads back");
    for f in &frames {
        let back = again
            .read_video_frame()
            .expect("written frame reads back")
            .expect("as many frames as written");
        assert!(back == *f, "frame round trip");
    }
});
