//! `unshear serve` end to end: the real binary listening on a free loopback port, driven by a
//! minimal HTTP/1.1 client (one request per connection). The good image must give the CLI's
//! answer; every bad input a 4xx JSON error with the server still up; eight clients at once
//! all answered. The browser test puts the bundled example through the page in headless
//! Chromium (skipped where none is installed). Every file here is made by the test.

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The README's example photo: the CLI estimates k = 0.3175 (JSON; +0.317 in its sentence).
fn example() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../assets/example/face-k0.30.png"
    ))
}

fn example_bytes() -> Vec<u8> {
    std::fs::read(example()).expect("example photo")
}

/// A running `unshear serve`, stopped when dropped.
struct Server {
    child: Child,
    addr: SocketAddr,
    /// From spawning to the printed URL.
    started_in: Duration,
}

impl Server {
    fn start(args: &[&str]) -> Self {
        let begin = Instant::now();
        let mut child = Command::new(env!("CARGO_BIN_EXE_unshear"))
            .args(["serve", "--port", "0"])
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start unshear serve");
        let mut line = String::new();
        BufReader::new(child.stdout.take().expect("stdout"))
            .read_line(&mut line)
            .expect("read the URL line");
        let started_in = begin.elapsed();
        let url = line
            .trim()
            .strip_prefix("listening on http://")
            .unwrap_or_else(|| panic!("the first line names the URL: {line:?}"));
        let addr = url.trim_end_matches('/').parse().expect("an address");
        Self {
            child,
            addr,
            started_in,
        }
    }

    fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    fn post(&self, path: &str, content_type: &str, body: &[u8]) -> Reply {
        request(
            self.addr,
            "POST",
            path,
            &[("Content-Type", content_type)],
            body,
        )
    }

    fn get(&self, path: &str) -> Reply {
        request(self.addr, "GET", path, &[], &[])
    }

    /// Checks that the server still answers.
    fn assert_up(&self) {
        let r = self.get("/api/health");
        assert_eq!(r.status, 200, "{}", r.text());
        assert_eq!(r.json()["status"], "ok");
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// An HTTP answer.
struct Reply {
    status: u16,
    headers: Vec<(String, String)>,
    body: Vec<u8>,
}

impl Reply {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }

    fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("JSON body ({e}): {}", self.text()))
    }

    /// Checks a typed JSON error: the status, the code, a message.
    fn assert_error(&self, status: u16, code: &str) -> String {
        assert_eq!(self.status, status, "{}", self.text());
        assert_eq!(self.header("content-type"), Some("application/json"));
        let v = self.json();
        assert_eq!(v["error"]["code"], code, "{v}");
        let message = v["error"]["message"].as_str().expect("message").to_string();
        assert!(!message.is_empty());
        message
    }
}

/// Sends one request (`Connection: close`) and reads the whole answer. The answer is read on
/// this thread while the body is written on another, so a server that answers before reading
/// all of a large body (413) is heard.
fn request(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> Reply {
    let mut head = format!("{method} {path} HTTP/1.1\r\nConnection: close\r\n");
    if !headers.iter().any(|(n, _)| n.eq_ignore_ascii_case("host")) {
        head.push_str(&format!("Host: {addr}\r\n"));
    }
    for (n, v) in headers {
        head.push_str(&format!("{n}: {v}\r\n"));
    }
    if !headers
        .iter()
        .any(|(n, _)| n.eq_ignore_ascii_case("content-length"))
    {
        head.push_str(&format!("Content-Length: {}\r\n", body.len()));
    }
    head.push_str("\r\n");
    let mut payload = head.into_bytes();
    payload.extend_from_slice(body);
    send(addr, move |stream| {
        let _ = stream.write_all(&payload);
    })
}

/// Connects, runs `write` on a second handle of the stream in a thread, and reads the answer.
fn send(addr: SocketAddr, write: impl FnOnce(&mut TcpStream) + Send + 'static) -> Reply {
    let mut stream = TcpStream::connect(addr).expect("connect");
    stream
        .set_read_timeout(Some(Duration::from_secs(60)))
        .expect("timeout");
    let mut writer = stream.try_clone().expect("clone");
    let sending = std::thread::spawn(move || write(&mut writer));
    let mut raw = Vec::new();
    let _ = stream.read_to_end(&mut raw);
    let _ = sending.join();
    parse_reply(&raw)
}

fn parse_reply(raw: &[u8]) -> Reply {
    let end = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .unwrap_or_else(|| panic!("no header end in {:?}", String::from_utf8_lossy(raw)));
    let head = String::from_utf8_lossy(&raw[..end]);
    let mut lines = head.split("\r\n");
    let status = lines
        .next()
        .and_then(|l| l.split(' ').nth(1))
        .and_then(|s| s.parse().ok())
        .expect("status line");
    let headers: Vec<(String, String)> = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(n, v)| (n.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    let mut body = raw[end + 4..].to_vec();
    if headers
        .iter()
        .any(|(n, v)| n == "transfer-encoding" && v.contains("chunked"))
    {
        body = dechunk(&body);
    }
    Reply {
        status,
        headers,
        body,
    }
}

fn dechunk(mut data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    while let Some(eol) = data.windows(2).position(|w| w == b"\r\n") {
        let size = usize::from_str_radix(String::from_utf8_lossy(&data[..eol]).trim(), 16)
            .expect("chunk size");
        if size == 0 {
            break;
        }
        out.extend_from_slice(&data[eol + 2..eol + 2 + size]);
        data = &data[eol + 2 + size + 2..];
    }
    out
}

/// A multipart/form-data body with the fields given (name, file name, bytes).
fn multipart(fields: &[(&str, Option<&str>, &[u8])]) -> (String, Vec<u8>) {
    let boundary = "unshear-test-boundary-7MA4YWxkTrZu0gW";
    let mut body = Vec::new();
    for (name, file, bytes) in fields {
        body.extend_from_slice(format!("--{boundary}\r\n").as_bytes());
        let disposition = match file {
            Some(f) => format!("form-data; name=\"{name}\"; filename=\"{f}\""),
            None => format!("form-data; name=\"{name}\""),
        };
        body.extend_from_slice(format!("Content-Disposition: {disposition}\r\n\r\n").as_bytes());
        body.extend_from_slice(bytes);
        body.extend_from_slice(b"\r\n");
    }
    body.extend_from_slice(format!("--{boundary}--\r\n").as_bytes());
    (format!("multipart/form-data; boundary={boundary}"), body)
}

/// `unshear estimate --json` on `path`, as the CLI prints it.
fn cli_estimate(path: &Path) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_unshear"))
        .args(["estimate", "--json"])
        .arg(path)
        .output()
        .expect("run estimate");
    assert!(out.status.success());
    common::json_lines(&out.stdout).remove(0)
}

/// The estimate of the example through the API is the CLI's object (the same `k`, 0.3175, and
/// every other field but the file's name), sent raw or as a form.
#[test]
fn the_example_estimates_as_with_the_cli() {
    let server = Server::start(&[]);
    let cli = cli_estimate(&example());
    assert_eq!(format!("{:+.3}", cli["k"].as_f64().expect("k")), "+0.318");
    let raw = server.post("/api/estimate?name=face.png", "image/png", &example_bytes());
    assert_eq!(raw.status, 200, "{}", raw.text());
    let mut api = raw.json();
    assert_eq!(api["file"], "face.png");
    assert_eq!(
        format!("{:.3}", api["k"].as_f64().expect("k")),
        format!("{:.3}", cli["k"].as_f64().expect("k"))
    );
    api["file"] = cli["file"].clone();
    assert_eq!(api, cli, "the whole object is the CLI's");
    let bytes = example_bytes();
    let (content_type, form) = multipart(&[("file", Some("face-k0.30.png"), &bytes)]);
    let form_reply = server.post("/api/estimate", &content_type, &form);
    assert_eq!(form_reply.status, 200, "{}", form_reply.text());
    assert_eq!(form_reply.json()["k"], cli["k"]);
    assert_eq!(form_reply.json()["file"], "face-k0.30.png");
    // The page's form: the CLI's sentence and the annotated picture besides.
    let page = server
        .post(
            "/api/estimate?annotate=true",
            "application/octet-stream",
            &bytes,
        )
        .json();
    assert_eq!(page["k"], cli["k"]);
    assert!(page["description"]
        .as_str()
        .expect("description")
        .starts_with("k = +0.317"));
    assert!(page["annotated"]
        .as_str()
        .expect("annotated")
        .starts_with("data:image/png;base64,iVBORw0KGgo"));
}

/// The corrected image comes back in the input's format with the shear used; a shear given is
/// used as it is; the canvas is honoured; the annotation is a PNG of the input's size.
#[test]
fn correct_and_annotate_return_images() {
    let server = Server::start(&[]);
    let bytes = example_bytes();
    let input = image::load_from_memory(&bytes).expect("decode");
    let r = server.post("/api/correct?name=dir/face.png", "image/png", &bytes);
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.header("content-type"), Some("image/png"));
    assert_eq!(r.header("x-unshear-k"), Some("0.3175"));
    assert_eq!(
        r.header("content-disposition"),
        Some("attachment; filename=\"face.unshear.png\"")
    );
    let out = image::load_from_memory(&r.body).expect("a PNG");
    assert_eq!((out.width(), out.height()), (input.width(), input.height()));
    let wide = server.post("/api/correct?k=0.2&canvas=expand", "image/png", &bytes);
    assert_eq!(wide.status, 200, "{}", wide.text());
    assert_eq!(wide.header("x-unshear-k"), Some("0.2000"));
    let wide = image::load_from_memory(&wide.body).expect("a PNG");
    assert!(wide.width() > input.width() && wide.height() == input.height());
    // A JPEG stays a JPEG; `format` asks for another.
    let jpeg = std::fs::read(common::fixture("subject01.normal.jpeg")).expect("fixture");
    let r = server.post("/api/correct?k=0.1", "image/jpeg", &jpeg);
    assert_eq!(r.header("content-type"), Some("image/jpeg"));
    assert!(r.body.starts_with(&[0xFF, 0xD8]));
    let r = server.post("/api/correct?k=0.1&format=webp", "image/jpeg", &jpeg);
    assert_eq!(r.header("content-type"), Some("image/webp"));
    let a = server.post("/api/annotate", "image/png", &bytes);
    assert_eq!(a.status, 200, "{}", a.text());
    assert_eq!(a.header("content-type"), Some("image/png"));
    assert_eq!(a.header("x-unshear-k"), Some("0.3175"));
    let annotated = image::load_from_memory(&a.body).expect("a PNG");
    assert_eq!(
        (annotated.width(), annotated.height()),
        (input.width(), input.height())
    );
}

/// A photo without a face: its estimate says so (k null); a correction without k is refused
/// with 422, one with k is made.
#[test]
fn no_face_is_422_where_a_face_is_needed() {
    let server = Server::start(&[]);
    let mut grey = Vec::new();
    image::DynamicImage::ImageLuma8(image::GrayImage::from_pixel(160, 120, image::Luma([128])))
        .write_to(
            &mut std::io::Cursor::new(&mut grey),
            image::ImageFormat::Png,
        )
        .expect("encode");
    let e = server.post("/api/estimate", "image/png", &grey);
    assert_eq!(e.status, 200);
    assert!(e.json()["k"].is_null());
    let message = server
        .post("/api/correct", "image/png", &grey)
        .assert_error(422, "no_face");
    assert!(message.contains("no face found"), "{message}");
    assert_eq!(
        server.post("/api/correct?k=0.1", "image/png", &grey).status,
        200
    );
}

/// Every bad input of the CLI's reliability tests, and every bad request: a 4xx JSON error
/// each, the server still up after all of them.
#[test]
fn bad_inputs_are_typed_4xx_errors() {
    let server = Server::start(&[]);
    let jpeg = std::fs::read(common::fixture("subject01.normal.jpeg")).expect("fixture");
    let png = example_bytes();
    let cases: Vec<(&str, Vec<u8>, u16, &str)> = vec![
        (
            "truncated JPEG",
            jpeg[..jpeg.len() / 3].to_vec(),
            400,
            "unreadable",
        ),
        (
            "truncated PNG",
            png[..png.len() / 2].to_vec(),
            400,
            "unreadable",
        ),
        (
            "text",
            b"hello, this is not a photo\n".to_vec(),
            400,
            "unreadable",
        ),
        ("empty", Vec::new(), 400, "empty"),
        (
            "decompression bomb",
            common::png_bomb(),
            413,
            "too_many_pixels",
        ),
    ];
    for endpoint in ["/api/estimate", "/api/correct", "/api/annotate"] {
        for (what, body, status, code) in &cases {
            let r = server.post(endpoint, "application/octet-stream", body);
            let message = r.assert_error(*status, code);
            if *what == "decompression bomb" {
                assert!(message.contains("100000x100000"), "{message}");
            }
        }
    }
    // A form whose file field is empty, and one with no file.
    let (t, form) = multipart(&[("file", Some("a.png"), b"")]);
    server
        .post("/api/estimate", &t, &form)
        .assert_error(400, "empty");
    let (t, form) = multipart(&[("note", None, b"hello")]);
    server
        .post("/api/estimate", &t, &form)
        .assert_error(400, "empty");
    // Wrong content types.
    for t in [
        "text/plain",
        "application/json",
        "application/x-www-form-urlencoded",
    ] {
        server
            .post("/api/estimate", t, &png)
            .assert_error(415, "unsupported_media_type");
    }
    // Bad parameters, methods and paths.
    for query in [
        "k=abc",
        "k=inf",
        "canvas=huge",
        "region=sky",
        "format=gif",
        "bogus=1",
    ] {
        server
            .post(&format!("/api/correct?{query}"), "image/png", &png)
            .assert_error(400, "bad_parameter");
    }
    server
        .get("/api/estimate")
        .assert_error(405, "method_not_allowed");
    server.get("/etc/passwd").assert_error(404, "not_found");
    // A page elsewhere whose name was made to point here (DNS rebinding) is refused.
    request(
        server.addr,
        "GET",
        "/api/health",
        &[("Host", "evil.example")],
        &[],
    )
    .assert_error(403, "forbidden_host");
    server.assert_up();
}

/// Uploads over `--max-upload` are refused with 413 while they are read: a declared 1 GB (of
/// which only a little is sent), and a chunked body with no declared length.
#[test]
fn uploads_over_the_limit_are_413() {
    let server = Server::start(&["--max-upload", "100000"]);
    // Under the limit (70 kB) it works.
    assert_eq!(
        server
            .post("/api/estimate", "image/png", &example_bytes())
            .status,
        200
    );
    let gigabyte = (1u64 << 30).to_string();
    let r = request(
        server.addr,
        "POST",
        "/api/estimate",
        &[
            ("Content-Type", "application/octet-stream"),
            ("Content-Length", &gigabyte),
        ],
        &vec![0u8; 1 << 20],
    );
    r.assert_error(413, "upload_too_large");
    let head = format!(
        "POST /api/correct HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\
         Content-Type: image/png\r\nTransfer-Encoding: chunked\r\n\r\n",
        server.addr
    );
    let r = send(server.addr, move |stream| {
        let _ = stream.write_all(head.as_bytes());
        let chunk = vec![0x55u8; 64 << 10];
        for _ in 0..32 {
            let mut piece = format!("{:x}\r\n", chunk.len()).into_bytes();
            piece.extend_from_slice(&chunk);
            piece.extend_from_slice(b"\r\n");
            if stream.write_all(&piece).is_err() {
                return;
            }
        }
        let _ = stream.write_all(b"0\r\n\r\n");
    });
    r.assert_error(413, "upload_too_large");
    // A form over the limit too.
    let big = vec![0u8; 200_000];
    let (t, form) = multipart(&[("file", Some("big.png"), &big)]);
    server
        .post("/api/estimate", &t, &form)
        .assert_error(413, "upload_too_large");
    server.assert_up();
}

/// Names sent with an upload are labels, never paths: a form's file name and field, and the
/// `name` parameter, with folders and `..` in them, are neither read nor written.
#[test]
fn path_names_in_form_fields_are_only_labels() {
    let server = Server::start(&[]);
    let dir = tempfile::tempdir().expect("temp");
    let target = dir.path().join("written-by-server.png");
    let target_name = target.display().to_string();
    let traversal = format!("../../../../..{target_name}");
    let bytes = example_bytes();
    let (t, form) = multipart(&[
        ("name", None, target_name.as_bytes()),
        ("path", None, b"/etc/passwd"),
        ("file", Some(&traversal), &bytes),
    ]);
    let r = server.post("/api/estimate", &t, &form);
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.json()["file"], "written-by-server.png");
    assert_eq!(
        format!("{:+.3}", r.json()["k"].as_f64().expect("k")),
        "+0.318"
    );
    // The name parameter: the same.
    let r = server.post("/api/correct?name=%2Fetc%2Fpasswd", "image/png", &bytes);
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(
        r.header("content-disposition"),
        Some("attachment; filename=\"passwd.unshear.png\"")
    );
    let (t, form) = multipart(&[("file", Some(&traversal), &bytes)]);
    let r = server.post("/api/correct", &t, &form);
    assert_eq!(r.status, 200, "{}", r.text());
    assert!(image::load_from_memory(&r.body).is_ok());
    assert!(!target.exists(), "nothing is written where a name points");
    assert_eq!(std::fs::read_dir(dir.path()).expect("list").count(), 0);
}

/// Eight clients at once, three requests each: every one answered, with the CLI's k.
#[test]
fn eight_concurrent_clients_are_all_answered() {
    let server = Server::start(&[]);
    let addr = server.addr;
    let bytes = std::sync::Arc::new(example_bytes());
    let clients: Vec<_> = (0..8)
        .map(|i| {
            let bytes = bytes.clone();
            std::thread::spawn(move || {
                (0..3)
                    .map(|j| {
                        let path = if (i + j) % 2 == 0 {
                            "/api/estimate"
                        } else {
                            "/api/correct"
                        };
                        let r =
                            request(addr, "POST", path, &[("Content-Type", "image/png")], &bytes);
                        (r.status, r.header("x-unshear-k").map(str::to_string), r)
                    })
                    .collect::<Vec<_>>()
            })
        })
        .collect();
    let mut answered = 0;
    for c in clients {
        for (status, k, r) in c.join().expect("client") {
            assert_eq!(status, 200, "{}", r.text());
            match k {
                Some(k) => assert_eq!(k, "0.3175"),
                None => assert_eq!(r.json()["k"], 0.3175),
            }
            answered += 1;
        }
    }
    assert_eq!(answered, 24);
    server.assert_up();
}

/// With one worker and no waiting, requests that find it busy get 503 with `Retry-After` and
/// the typed error; the others are answered.
#[test]
fn a_busy_server_answers_503_with_retry_after() {
    let server = Server::start(&["--jobs", "1", "--wait", "0"]);
    let addr = server.addr;
    // A larger picture, so that each request holds the worker a while.
    let big = image::load_from_memory(&example_bytes())
        .expect("decode")
        .resize(1600, 1000, image::imageops::FilterType::Triangle);
    let mut bytes = Vec::new();
    big.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .expect("encode");
    let bytes = std::sync::Arc::new(bytes);
    let barrier = std::sync::Arc::new(std::sync::Barrier::new(6));
    let clients: Vec<_> = (0..6)
        .map(|_| {
            let (bytes, barrier) = (bytes.clone(), barrier.clone());
            std::thread::spawn(move || {
                barrier.wait();
                request(
                    addr,
                    "POST",
                    "/api/estimate",
                    &[("Content-Type", "image/png")],
                    &bytes,
                )
            })
        })
        .collect();
    let replies: Vec<Reply> = clients
        .into_iter()
        .map(|c| c.join().expect("client"))
        .collect();
    let busy = replies.iter().filter(|r| r.status == 503).count();
    for r in &replies {
        if r.status == 503 {
            r.assert_error(503, "busy");
            assert_eq!(r.header("retry-after"), Some("2"));
        } else {
            assert_eq!(r.status, 200, "{}", r.text());
        }
    }
    assert!((1..6).contains(&busy), "{busy} of 6 were busy");
    server.assert_up();
}

/// The page, its script and styles are served from the binary; the server starts quickly.
#[test]
fn the_page_is_built_in() {
    let server = Server::start(&[]);
    eprintln!("started in {:?}", server.started_in);
    assert!(server.started_in < Duration::from_secs(10));
    let page = server.get("/");
    assert_eq!(page.status, 200);
    assert!(page.text().contains("<script src=\"/app.js\"></script>"));
    assert!(!page.text().contains("http"), "no CDN or other site");
    assert!(server.get("/app.js").text().contains("/api/estimate"));
    assert_eq!(server.get("/style.css").status, 200);
    assert_eq!(server.get("/example.png").body, example_bytes());
}

/// Headless Chromium opens `/?demo=example`: the page puts the bundled example through the API
/// and shows the CLI's k, +0.318 (0.3175); a screenshot of it is made. `/?demo=bad`: a photo without a
/// face and a text file each get their message.
#[test]
fn the_page_shows_the_clis_k_in_a_browser() {
    let Some(chromium) = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|c| {
            Command::new(c)
                .arg("--version")
                .output()
                .is_ok_and(|o| o.status.success())
        })
    else {
        let note = "skipped: no chromium installed (apt-get install chromium)\n";
        let _ = std::io::stderr().write_all(note.as_bytes());
        return;
    };
    let server = Server::start(&[]);
    let dir = tempfile::tempdir().expect("temp");
    let browser = |extra: &[&str], demo: &str| {
        let out = Command::new(chromium)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
                "--hide-scrollbars",
                "--virtual-time-budget=20000",
                "--window-size=900,1000",
            ])
            .arg(format!(
                "--user-data-dir={}",
                dir.path().join("profile").display()
            ))
            .args(extra)
            .arg(server.url(&format!("/?demo={demo}")))
            .current_dir(dir.path())
            .stderr(Stdio::null())
            .output()
            .expect("run chromium");
        assert!(out.status.success(), "chromium failed");
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let dom = browser(&["--dump-dom"], "example");
    assert!(
        dom.contains("data-k=\"+0.318\">k = +0.318<"),
        "the page shows k = +0.318: {dom}"
    );
    let shot = dir.path().join("page.png");
    browser(&[&format!("--screenshot={}", shot.display())], "example");
    let picture = image::open(&shot).expect("a screenshot");
    assert_eq!((picture.width(), picture.height()), (900, 1000));
    // A photo without a face and a file that is no image: each says so in words.
    let dom = browser(&["--dump-dom"], "bad");
    assert!(dom.contains(">No usable face<"), "{dom}");
    assert!(dom.contains("no face found. Set k by hand"), "{dom}");
    assert!(
        dom.contains("This file could not be read as an image."),
        "{dom}"
    );
}

/// The server's resident memory now and at its peak, kB (Linux: /proc).
fn memory_kb(server: &Server) -> Option<(u64, u64)> {
    let status = std::fs::read_to_string(format!("/proc/{}/status", server.child.id())).ok()?;
    let field = |name: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.split_whitespace().next()?.parse().ok())
    };
    Some((field("VmRSS:")?, field("VmHWM:")?))
}

/// The median of three timings of `f`.
fn median_of_3(mut f: impl FnMut()) -> Duration {
    let mut times: Vec<Duration> = (0..3)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed()
        })
        .collect();
    times.sort();
    times[1]
}

/// The figures of docs/serve.md (run with `--release -- --ignored --nocapture`): the start
/// time, a 12-megapixel JPEG through the API against the CLI, and the load test, 200 requests
/// from 8 clients on loopback, every answer checked, the memory before and after.
#[test]
#[ignore = "a measurement: cargo test --release -p unshear-cli --test serve -- --ignored --nocapture"]
fn measure_start_12_megapixels_and_load() {
    let server = Server::start(&[]);
    let t = Instant::now();
    server.assert_up();
    println!(
        "start: URL printed after {:.0} ms, first answer {:.1} ms later",
        server.started_in.as_secs_f64() * 1e3,
        t.elapsed().as_secs_f64() * 1e3
    );
    // A 12-megapixel JPEG: the example enlarged to 4480 x 2736.
    let dir = tempfile::tempdir().expect("temp");
    let photo = dir.path().join("12mp.jpg");
    image::load_from_memory(&example_bytes())
        .expect("decode")
        .resize_exact(4480, 2736, image::imageops::FilterType::CatmullRom)
        .to_rgb8()
        .save(&photo)
        .expect("save");
    let bytes = std::fs::read(&photo).expect("read");
    let cli = median_of_3(|| {
        cli_estimate(&photo);
    });
    let mut api_k = serde_json::Value::Null;
    let api = median_of_3(|| {
        let r = server.post("/api/estimate", "image/jpeg", &bytes);
        assert_eq!(r.status, 200, "{}", r.text());
        api_k = r.json()["k"].clone();
    });
    assert_eq!(api_k, cli_estimate(&photo)["k"]);
    // Eight clients sending the 12-MP photo at once, twice each: the peak memory is bounded by
    // the workers (--jobs), not by the clients.
    let photo_bytes = std::sync::Arc::new(bytes.clone());
    let clients: Vec<_> = (0..8)
        .map(|_| {
            let (bytes, addr) = (photo_bytes.clone(), server.addr);
            std::thread::spawn(move || {
                for _ in 0..2 {
                    let r = request(
                        addr,
                        "POST",
                        "/api/estimate",
                        &[("Content-Type", "image/jpeg")],
                        &bytes,
                    );
                    assert_eq!(r.status, 200, "{}", r.text());
                }
            })
        })
        .collect();
    for c in clients {
        c.join().expect("every 12-MP answer right");
    }
    println!(
        "8 clients x 2 requests of the 12-MP photo: resident memory (now, peak) kB {:?}",
        memory_kb(&server)
    );
    println!(
        "12 MP JPEG ({} bytes, k = {api_k}): CLI estimate {:.2} s, API {:.2} s, ratio {:.2}",
        bytes.len(),
        cli.as_secs_f64(),
        api.as_secs_f64(),
        api.as_secs_f64() / cli.as_secs_f64()
    );
    // The load test.
    let example = std::sync::Arc::new(example_bytes());
    let load = |requests_per_client: usize| {
        let t = Instant::now();
        let clients: Vec<_> = (0..8)
            .map(|i| {
                let (bytes, addr) = (example.clone(), server.addr);
                std::thread::spawn(move || {
                    for j in 0..requests_per_client {
                        let path = ["/api/estimate", "/api/correct"][(i + j) % 2];
                        let r =
                            request(addr, "POST", path, &[("Content-Type", "image/png")], &bytes);
                        assert_eq!(r.status, 200, "{}", r.text());
                        let k = match r.header("x-unshear-k") {
                            Some(k) => k.to_string(),
                            None => format!("{:.4}", r.json()["k"].as_f64().expect("k")),
                        };
                        assert_eq!(k, "0.3175");
                    }
                })
            })
            .collect();
        for c in clients {
            c.join().expect("every answer right");
        }
        t.elapsed()
    };
    load(1);
    let before = memory_kb(&server);
    let took = load(25);
    let after = memory_kb(&server);
    println!(
        "load: 200 requests from 8 clients in {:.2} s ({:.0} requests/s), all answered right; \
         resident memory (now, peak) kB before {before:?}, after {after:?}",
        took.as_secs_f64(),
        200.0 / took.as_secs_f64()
    );
    server.assert_up();
}
