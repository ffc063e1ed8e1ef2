//! `unshear._unshear`: the Python binding of the `unshear` library (see `python/unshear/__init__.pyi`
//! for the API as Python sees it, and `docs/python.md`).
//!
//! Every call copies its arrays into owned image buffers with the GIL held, then releases the GIL
//! (`Python::detach`) for all the work in Rust, and takes it again only to build the results.

mod args;
mod config;
mod image;
mod report;
mod video;

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use pyo3::exceptions::{
    PyFileExistsError, PyFileNotFoundError, PyIsADirectoryError, PyOSError, PyPermissionError,
    PyRuntimeError, PyTypeError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;

use ::image::DynamicImage;
use unshear::imageio::{self, WriteOptions, DEFAULT_MAX_PIXELS};
use unshear::pipeline::{CorrectOptions, Region};
use unshear::warp::{Canvas, Interpolation};
use unshear::{Error, ImageReport, Shear};

use crate::config::{build, PyConfig, Use};
use crate::image::{from_array, to_array, Input, Layout};
use crate::report::{Face, Report};

pyo3::create_exception!(
    unshear,
    NoFaceError,
    PyValueError,
    "No face gave an accepted estimate and no shear was given, so there is nothing to correct by."
);

/// The library's error as a Python exception carrying its message: files' errors as `OSError`
/// (`FileNotFoundError`, `PermissionError`, ... by the operating system's reason), refused
/// writes as `FileExistsError`, bad values as `ValueError`.
pub fn to_pyerr(e: Error) -> PyErr {
    let message = e.to_string();
    match &e {
        Error::Io { source, .. } => match source.kind() {
            std::io::ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
            std::io::ErrorKind::PermissionDenied => PyPermissionError::new_err(message),
            std::io::ErrorKind::AlreadyExists => PyFileExistsError::new_err(message),
            std::io::ErrorKind::IsADirectory => PyIsADirectoryError::new_err(message),
            _ => PyOSError::new_err(message),
        },
        Error::Image { .. } | Error::TooLarge { .. } | Error::FileTooLarge { .. } => {
            PyOSError::new_err(message)
        }
        Error::Refused { .. } => PyFileExistsError::new_err(message),
        Error::InvalidArgument(_) | Error::Video(_) => PyValueError::new_err(message),
        _ => PyRuntimeError::new_err(message),
    }
}

fn region_of(name: &str) -> PyResult<Region> {
    match name {
        "image" => Ok(Region::Image),
        "face" => Ok(Region::Face),
        _ => Err(PyValueError::new_err(format!(
            "region must be \"image\" or \"face\", got {name:?}"
        ))),
    }
}

fn canvas_of(name: &str) -> PyResult<Canvas> {
    match name {
        "same" => Ok(Canvas::Same),
        "expand" => Ok(Canvas::Expand),
        "crop" => Ok(Canvas::Crop),
        _ => Err(PyValueError::new_err(format!(
            "canvas must be \"same\", \"expand\" or \"crop\", got {name:?}"
        ))),
    }
}

pub fn interp_of(name: &str) -> PyResult<Interpolation> {
    match name {
        "linear" => Ok(Interpolation::Linear),
        "cubic" => Ok(Interpolation::Cubic),
        _ => Err(PyValueError::new_err(format!(
            "interp must be \"linear\" or \"cubic\", got {name:?}"
        ))),
    }
}

/// The rolling-shutter corrector: the built-in models with one set of settings, built once and
/// used for any number of images, from any number of threads.
#[pyclass(name = "Unshear", module = "unshear", frozen)]
struct PyUnshear {
    inner: unshear::Unshear,
    config: PyConfig,
    max_pixels: u64,
    /// The thread pool of the last `estimate_many(threads=N)`, with its size: kept for the
    /// next call with the same `N`, replaced (its threads ended) by one with another, so
    /// calls with ever new sizes do not pile up threads.
    pool: Mutex<Option<(usize, Arc<rayon::ThreadPool>)>>,
}

impl PyUnshear {
    fn pool(&self, threads: usize) -> PyResult<Arc<rayon::ThreadPool>> {
        let mut cached = self
            .pool
            .lock()
            .map_err(|_| PyRuntimeError::new_err("thread pool cache poisoned"))?;
        if let Some((n, pool)) = cached.as_ref() {
            if *n == threads {
                return Ok(pool.clone());
            }
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| PyRuntimeError::new_err(format!("starting {threads} threads: {e}")))?;
        let pool = Arc::new(pool);
        *cached = Some((threads, pool.clone()));
        Ok(pool)
    }

    fn input(&self, py: Python<'_>, image: &Bound<'_, PyAny>, bgr: bool) -> PyResult<Input> {
        from_array(py, image, bgr, self.max_pixels)
    }
}

#[pymethods]
impl PyUnshear {
    #[new]
    #[pyo3(signature = (*, max_pixels = DEFAULT_MAX_PIXELS, **config))]
    fn new(
        py: Python<'_>,
        #[pyo3(from_py_with = args::max_pixels)] max_pixels: u64,
        config: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let cfg = PyConfig::from_kwargs("Unshear", config)?;
        let inner = py.detach(|| build(&cfg, Use::Stills)).map_err(to_pyerr)?;
        Ok(Self {
            inner,
            config: cfg,
            max_pixels,
            pool: Mutex::new(None),
        })
    }

    /// The settings, as keyword arguments of ``Unshear(**config)``.
    #[getter]
    fn config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.config.to_dict(py)
    }

    /// The largest image accepted, in pixels.
    #[getter]
    fn max_pixels(&self) -> u64 {
        self.max_pixels
    }

    /// Finds the faces in ``image`` and estimates the shear from each.
    #[pyo3(signature = (image, *, bgr = false))]
    fn estimate(&self, py: Python<'_>, image: &Bound<'_, PyAny>, bgr: bool) -> PyResult<Report> {
        let input = self.input(py, image, bgr)?;
        let inner = py.detach(|| self.inner.estimate(&input.image));
        Ok(Report { inner })
    }

    /// ``estimate`` on every image, in parallel.
    #[pyo3(signature = (images, *, threads = None, bgr = false))]
    fn estimate_many(
        &self,
        py: Python<'_>,
        images: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = args::threads)] threads: Option<usize>,
        bgr: bool,
    ) -> PyResult<Vec<Report>> {
        let ndim = images
            .getattr("ndim")
            .ok()
            .and_then(|n| n.extract::<usize>().ok());
        if ndim.is_some_and(|n| n < 4) {
            // One image is iterable by rows, which would be read as many one-row images (a
            // 4-D array is a stack of images, as Ray Data hands them over).
            return Err(PyTypeError::new_err(
                "estimate_many takes a list (or any iterable, or a 4-D stack) of images, not \
                 one image; use estimate for one image",
            ));
        }
        let pool = threads.map(|n| self.pool(n)).transpose()?;
        let inputs: Vec<DynamicImage> = images
            .try_iter()?
            .map(|item| Ok(self.input(py, &item?, bgr)?.image))
            .collect::<PyResult<_>>()?;
        let reports: Vec<ImageReport> = py.detach(|| {
            let run = || {
                inputs
                    .par_iter()
                    .map(|img| self.inner.estimate(img))
                    .collect()
            };
            match &pool {
                Some(pool) => pool.install(run),
                None => run(),
            }
        });
        Ok(reports.into_iter().map(|inner| Report { inner }).collect())
    }

    /// Removes the shear from ``image``: the estimated one (or ``report``'s), or ``k``; with
    /// ``blur`` (pixels, or ``"auto"``: found from the image, row by row) a motion blur along
    /// the rows first, before the faces are read.
    #[pyo3(signature = (image, k = None, *, region = "image", canvas = "same", interp = "linear", report = None, bgr = false, blur = None))]
    #[allow(clippy::too_many_arguments)]
    fn correct<'py>(
        &self,
        py: Python<'py>,
        image: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = args::optional_k)] k: Option<f64>,
        region: &str,
        canvas: &str,
        interp: &str,
        report: Option<PyRef<'_, Report>>,
        bgr: bool,
        blur: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let blur = blur.map(args::blur).transpose()?.flatten();
        let options = CorrectOptions {
            region: region_of(region)?,
            canvas: canvas_of(canvas)?,
            interpolation: interp_of(interp)?,
            k,
            blur: None,
        };
        let given = report.map(|r| r.inner.clone());
        let Input { image, layout } = self.input(py, image, bgr)?;
        if let Some(r) = &given {
            if (r.width, r.height) != (image.width(), image.height()) {
                return Err(PyValueError::new_err(format!(
                    "the report is of a {}x{} image, this image is {}x{}",
                    r.width,
                    r.height,
                    image.width(),
                    image.height()
                )));
            }
        }
        let reason = no_change_reason(&options);
        let result = py.detach(|| -> Result<DynamicImage, Failure> {
            // A motion blur is removed first, so the faces are read in the sharp picture.
            let mut image = image;
            if let Some(length) = blur {
                unshear::Unshear::remove_blur(&mut image, length).map_err(to_pyerr)?;
            }
            // The estimate only where it is needed: not for a whole-image correction by `k`.
            let needs_faces = options.region == Region::Face || options.k.is_none();
            let report = match given {
                Some(r) => r,
                None if needs_faces => self.inner.estimate(&image),
                None => ImageReport::empty(image.width(), image.height()),
            };
            if !options.changes(&report) {
                return Err(Failure::NoFace(Box::new(report)));
            }
            unshear::Unshear::correct(&image, &report, &options).map_err(|e| to_pyerr(e).into())
        });
        let result = result.map_err(|f| f.into_pyerr(py, reason))?;
        to_array(py, result, layout)
    }

    /// ``estimate`` of an image file, as ``unshear estimate FILE`` reports it: a photo its EXIF
    /// orientation turns a quarter was read out by columns, and its shear is vertical.
    fn estimate_file(&self, py: Python<'_>, path: PathBuf) -> PyResult<Report> {
        let max_pixels = self.max_pixels;
        let inner = py
            .detach(|| {
                let (img, metadata) = imageio::read_image_with_metadata(&path, max_pixels)?;
                Ok::<_, Error>(self.inner.estimate_photo(&img, &metadata))
            })
            .map_err(to_pyerr)?;
        Ok(Report { inner })
    }

    /// Corrects the image file ``src`` into ``dst`` as ``unshear correct`` does: the colour
    /// profile and EXIF block kept, written atomically, never over ``src``.
    #[pyo3(signature = (src, dst, k = None, *, region = "image", canvas = "same", interp = "linear", overwrite = false, jpeg_quality = 95))]
    #[allow(clippy::too_many_arguments)]
    fn correct_file(
        &self,
        py: Python<'_>,
        src: PathBuf,
        dst: PathBuf,
        #[pyo3(from_py_with = args::optional_k)] k: Option<f64>,
        region: &str,
        canvas: &str,
        interp: &str,
        overwrite: bool,
        #[pyo3(from_py_with = args::jpeg_quality)] jpeg_quality: u8,
    ) -> PyResult<Report> {
        check_output_format(&dst)?;
        let options = CorrectOptions {
            region: region_of(region)?,
            canvas: canvas_of(canvas)?,
            interpolation: interp_of(interp)?,
            k,
            blur: None,
        };
        let max_pixels = self.max_pixels;
        let reason = no_change_reason(&options);
        let inner = py.detach(|| -> Result<ImageReport, Failure> {
            let (img, metadata) =
                imageio::read_image_with_metadata(&src, max_pixels).map_err(to_pyerr)?;
            let report = self.inner.estimate_photo(&img, &metadata);
            if !options.changes(&report) {
                return Err(Failure::NoFace(Box::new(report)));
            }
            let fixed = unshear::Unshear::correct(&img, &report, &options).map_err(to_pyerr)?;
            drop(img);
            let write = WriteOptions {
                overwrite,
                jpeg_quality,
                protected: vec![src.clone()],
                metadata,
            };
            imageio::write_image_atomic(&fixed, &dst, write).map_err(to_pyerr)?;
            Ok(report)
        });
        let inner = inner.map_err(|f| f.into_pyerr(py, reason))?;
        Ok(Report { inner })
    }

    /// ``Unshear(...)`` with the settings that differ from the defaults.
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let ours = self.config.to_dict(py)?;
        let defaults = PyConfig::default().to_dict(py)?;
        let mut parts = Vec::new();
        for key in config::keys() {
            let value = ours.as_any().get_item(key)?;
            if !value.eq(defaults.as_any().get_item(key)?)? {
                parts.push(format!("{key}={}", value.repr()?));
            }
        }
        if self.max_pixels != DEFAULT_MAX_PIXELS {
            parts.push(format!("max_pixels={}", self.max_pixels));
        }
        Ok(format!("Unshear({})", parts.join(", ")))
    }
}

/// Reads an image file (format from the content, EXIF orientation applied, size checked before
/// decoding) into a numpy array.
#[pyfunction]
#[pyo3(signature = (path, *, bgr = false, max_pixels = DEFAULT_MAX_PIXELS))]
fn read(
    py: Python<'_>,
    path: PathBuf,
    bgr: bool,
    #[pyo3(from_py_with = args::max_pixels)] max_pixels: u64,
) -> PyResult<Bound<'_, PyAny>> {
    let img = py
        .detach(|| imageio::read_image(&path, max_pixels))
        .map_err(to_pyerr)?;
    let two_d = !img.color().has_color() && !img.color().has_alpha();
    let bgr = bgr && img.color().has_color();
    to_array(py, img, Layout { two_d, bgr })
}

/// Why correcting with `report` would change nothing (see [`CorrectOptions::changes`]).
/// Why a correction did not happen, from work done without the GIL: `NoFaceError` needs the GIL
/// to carry its report.
enum Failure {
    /// Nothing to correct by: the report that found no face (or refused every estimate).
    NoFace(Box<ImageReport>),
    /// Any other error.
    Error(PyErr),
}

impl From<PyErr> for Failure {
    fn from(e: PyErr) -> Self {
        Failure::Error(e)
    }
}

impl Failure {
    /// The Python exception: `NoFaceError` with the report as its `report` attribute (what
    /// was found, for the caller's record, without estimating again).
    fn into_pyerr(self, py: Python<'_>, reason: &'static str) -> PyErr {
        match self {
            Failure::Error(e) => e,
            Failure::NoFace(inner) => {
                let err = NoFaceError::new_err(reason);
                let attached = Py::new(py, Report { inner: *inner })
                    .and_then(|report| err.value(py).setattr("report", report));
                match attached {
                    Ok(()) => err,
                    Err(e) => e,
                }
            }
        }
    }
}

fn no_change_reason(options: &CorrectOptions) -> &'static str {
    if options.k.is_some() {
        "no face found: a face-region correction needs a detected face"
    } else {
        "no face found with an accepted estimate; give k= to correct anyway"
    }
}

/// An error for an output path whose extension names no format `write` writes.
fn check_output_format(path: &std::path::Path) -> PyResult<()> {
    if imageio::output_format_supported(path) {
        return Ok(());
    }
    Err(PyValueError::new_err(format!(
        "{}: unsupported output format (use .jpg, .png, .pgm/.ppm, .bmp, .tif or .webp)",
        path.display()
    )))
}

/// Writes an image array to ``path`` (format from the extension), atomically.
#[pyfunction]
#[pyo3(signature = (path, image, *, bgr = false, overwrite = true, jpeg_quality = 95))]
fn write(
    py: Python<'_>,
    path: PathBuf,
    image: &Bound<'_, PyAny>,
    bgr: bool,
    overwrite: bool,
    #[pyo3(from_py_with = args::jpeg_quality)] jpeg_quality: u8,
) -> PyResult<()> {
    check_output_format(&path)?;
    let input = from_array(py, image, bgr, u64::MAX)?;
    let options = WriteOptions {
        overwrite,
        jpeg_quality,
        ..Default::default()
    };
    py.detach(|| imageio::write_image_atomic(&input.image, &path, options))
        .map_err(to_pyerr)
}

/// Applies a shear, as a rolling shutter would: ``x' = x + k (y - pivot)``.
#[pyfunction]
#[pyo3(signature = (image, k, *, pivot = None, canvas = "same", interp = "linear"))]
fn distort<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    #[pyo3(from_py_with = args::k)] k: f64,
    #[pyo3(from_py_with = args::pivot)] pivot: Option<f64>,
    canvas: &str,
    interp: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let canvas = canvas_of(canvas)?;
    let interp = interp_of(interp)?;
    let Input { image, layout } = from_array(py, image, false, DEFAULT_MAX_PIXELS)?;
    let shear = match pivot {
        Some(c) => Shear::new(k, c),
        None => Shear::about_middle(k, image.height()),
    };
    let (out, _) = py
        .detach(|| unshear::warp::try_apply_shear(&image, shear, interp, canvas))
        .map_err(to_pyerr)?;
    to_array(py, out, layout)
}

/// The settings ``Unshear(**config)`` and ``VideoCorrector(**config)`` take, one dict each:
/// ``name``, ``kind`` (``"flag"``, ``"integer"``, ``"number"``, ``"numbers"`` or
/// ``"choice"``), ``choices`` (the names of a choice, else empty), ``default`` and ``help``
/// (text, as ``unshear --help`` gives them).
#[pyfunction]
fn options(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    use unshear::config::OptionKind;
    unshear::config::options()
        .iter()
        .map(|o| {
            let d = PyDict::new(py);
            let (kind, choices): (&str, &[&str]) = match o.kind {
                OptionKind::Flag => ("flag", &[]),
                OptionKind::Integer => ("integer", &[]),
                OptionKind::Number => ("number", &[]),
                OptionKind::Numbers => ("numbers", &[]),
                OptionKind::Choice(names) => ("choice", names),
            };
            d.set_item("name", o.name)?;
            d.set_item("kind", kind)?;
            d.set_item("choices", choices.to_vec())?;
            d.set_item("default", o.default)?;
            d.set_item("help", o.help)?;
            Ok(d)
        })
        .collect()
}

#[pymodule]
fn _unshear(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyUnshear>()?;
    m.add_class::<Report>()?;
    m.add_class::<Face>()?;
    m.add_class::<video::VideoCorrector>()?;
    m.add_class::<video::Frame>()?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(write, m)?)?;
    m.add_function(wrap_pyfunction!(distort, m)?)?;
    m.add_function(wrap_pyfunction!(options, m)?)?;
    let no_face = m.py().get_type::<NoFaceError>();
    // The class's default; each raised error carries the report that found no face.
    no_face.setattr("report", m.py().None())?;
    m.add("NoFaceError", no_face)?;
    m.add("DEFAULT_MAX_PIXELS", DEFAULT_MAX_PIXELS)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
