//! `unshear.VideoCorrector`: frames pushed one at a time through the library's
//! `VideoProcessor` (the tracking, the temporal filter and the smoother of `unshear video`).

use std::sync::Mutex;

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyType};

use unshear::imageio::DEFAULT_MAX_PIXELS;
use unshear::video::FilterParams;
use unshear::video::TrackerParams;
use unshear::video::{
    FrameResult, KSource, ProcessOptions, ShearSource, VideoFrame, VideoProcessor,
};
use unshear::Readout;

use crate::args;
use crate::config::{build, PyConfig, Use};
use crate::image::{from_array, to_array, Input, Layout};
use crate::report::{faces, from_state, state, Face};
use crate::{interp_of, to_pyerr};

type Processor<'a> = VideoProcessor<'a>;

self_cell::self_cell!(
    /// A corrector and the processor that borrows it, kept together.
    struct Stream {
        owner: unshear::Unshear,
        #[covariant]
        dependent: Processor,
    }
);

/// What the first frame fixed: every later frame must have the same size and layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Shape {
    width: u32,
    height: u32,
    color: ::image::ColorType,
    layout: Layout,
}

/// Where a stream is: pushed frame by frame, or read in two passes (`analyse` then
/// `replay`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Fresh,
    Pushing,
    Analysing,
    Replaying,
}

struct State {
    stream: Stream,
    shape: Option<Shape>,
    finished: bool,
    phase: Phase,
}

impl State {
    /// Checks that `shape` is the first frame's (fixing it on the first frame) and that the
    /// stream may go to `phase` from where it is.
    fn admit(&mut self, shape: Shape, phase: Phase) -> PyResult<()> {
        if self.finished {
            return Err(bad(
                "finish() was called: this stream is over (make a new VideoCorrector)".into(),
            ));
        }
        let allowed = match phase {
            Phase::Pushing => matches!(self.phase, Phase::Fresh | Phase::Pushing),
            Phase::Analysing => matches!(self.phase, Phase::Fresh | Phase::Analysing),
            Phase::Replaying => self.phase == Phase::Replaying,
            Phase::Fresh => false,
        };
        if !allowed {
            return Err(bad(match phase {
                Phase::Pushing => "push() after analyse(): a stream in two passes takes \
                                   analyse(), end_analysis(), then replay()"
                    .into(),
                Phase::Analysing => "analyse() after push() or end_analysis(): the first pass \
                                     comes first, on a new VideoCorrector"
                    .into(),
                _ => "replay() before end_analysis(): analyse every frame first".into(),
            }));
        }
        match self.shape {
            None => self.shape = Some(shape),
            Some(first) if first != shape => {
                return Err(bad(format!(
                    "every frame must have the first frame's size and layout: {}x{} {:?}, got {}x{} {:?}",
                    first.width, first.height, first.color, shape.width, shape.height, shape.color
                )));
            }
            Some(_) => {}
        }
        self.phase = phase;
        Ok(())
    }
}

/// One corrected frame: the image (in the layout and dtype it was pushed in) and its shears.
#[pyclass(module = "unshear", frozen)]
pub struct Frame {
    image: Py<PyAny>,
    result: FrameResult,
}

#[pymethods]
impl Frame {
    /// The frame, corrected by ``k_applied`` (unchanged with ``correct=False``).
    #[getter]
    fn image(&self, py: Python<'_>) -> Py<PyAny> {
        self.image.clone_ref(py)
    }

    /// The frame's number, from 0.
    #[getter]
    fn index(&self) -> u64 {
        self.result.index
    }

    /// The temporally filtered and smoothed shear of this frame.
    #[getter]
    fn k(&self) -> f64 {
        self.result.k
    }

    /// This frame's own estimate (the median of its faces'), ``None`` without a usable face.
    #[getter]
    fn k_raw(&self) -> Option<f64> {
        self.result.k_raw
    }

    /// The causal filter's shear after this frame (from this and earlier frames only).
    #[getter]
    fn k_causal(&self) -> f64 {
        self.result.k_causal
    }

    /// The shear the frame was corrected by, ``None`` with ``correct=False``.
    #[getter]
    fn k_applied(&self) -> Option<f64> {
        self.result.k_applied
    }

    /// Every tracked face with an estimate.
    #[getter]
    fn faces(&self) -> Vec<Face> {
        faces(&self.result.faces)
    }

    /// Where ``k`` came from: ``"motion"`` (image velocity times the line time), ``"faces"``
    /// or ``"none"`` (no measurement: the last ``k`` held or decaying).
    #[getter]
    fn k_source(&self) -> &'static str {
        source_name(self.result.k_source)
    }

    /// The readout fraction in use for this frame (given, or calibrated so far), or ``None``.
    #[getter]
    fn readout_fraction(&self) -> Option<f64> {
        self.result.readout_fraction
    }

    /// The image velocity ``(vx, vy)`` at the middle row's time, pixels per frame, when
    /// measured.
    #[getter]
    fn velocity(&self) -> Option<(f64, f64)> {
        self.result.velocity.map(|[x, y]| (x, y))
    }

    /// The motion blur removed at the middle row, pixels (``deblur_exposure``; frames corrected
    /// from motion only), or ``None``.
    #[getter]
    fn blur(&self) -> Option<f64> {
        self.result.blur
    }

    /// The frame's line of ``unshear video --json`` as a dict (``frame``, ``k_raw``, ``k``,
    /// ``faces``), not rounded.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("frame", self.result.index)?;
        d.set_item("k_raw", self.result.k_raw)?;
        d.set_item("k", self.result.k)?;
        d.set_item("k_source", source_name(self.result.k_source))?;
        d.set_item("readout_fraction", self.result.readout_fraction)?;
        d.set_item("velocity", self.velocity())?;
        if let Some(b) = self.result.blur {
            d.set_item("blur", b)?;
        }
        let list = PyList::empty(py);
        for f in self.faces() {
            list.append(f.to_dict(py)?)?;
        }
        d.set_item("faces", list)?;
        Ok(d)
    }

    /// Pickles as the frame's image and full state (`copy` and `multiprocessing` use the same).
    #[allow(clippy::type_complexity)]
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, (Py<PyAny>, Bound<'py, PyAny>))> {
        let py = slf.py();
        let restore = slf.get_type().getattr("_from_state")?;
        let frame = slf.get();
        Ok((
            restore,
            (frame.image.clone_ref(py), state(py, &frame.result)?),
        ))
    }

    #[classmethod]
    fn _from_state(
        _cls: &Bound<'_, PyType>,
        image: Py<PyAny>,
        state: &Bound<'_, PyAny>,
    ) -> PyResult<Self> {
        Ok(Self {
            image,
            result: from_state(state)?,
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "Frame(index={}, k={:.4}, k_raw={}, faces={})",
            self.result.index,
            self.result.k,
            self.result
                .k_raw
                .map_or("None".to_string(), |k| format!("{k:.4}")),
            self.result.faces.len()
        )
    }
}

fn source_name(s: ShearSource) -> &'static str {
    match s {
        ShearSource::Motion => "motion",
        ShearSource::Faces => "faces",
        ShearSource::None => "none",
    }
}

/// A video stream: push frames in order, get them back corrected, with the tracking and the
/// temporal filter of ``unshear video``.
#[pyclass(module = "unshear", frozen)]
pub struct VideoCorrector {
    state: Mutex<State>,
    bgr: bool,
    max_pixels: u64,
    smoothing_lag: usize,
}

fn bad(message: String) -> PyErr {
    PyValueError::new_err(message)
}

impl VideoCorrector {
    /// A pushed array as an image, and its shape.
    fn frame_in(&self, py: Python<'_>, frame: &Bound<'_, PyAny>) -> PyResult<(Input, Shape)> {
        let input = from_array(py, frame, self.bgr, self.max_pixels)?;
        let shape = Shape {
            width: input.image.width(),
            height: input.image.height(),
            color: input.image.color(),
            layout: input.layout,
        };
        Ok((input, shape))
    }

    fn lock(&self) -> PyResult<std::sync::MutexGuard<'_, State>> {
        self.state
            .lock()
            .map_err(|_| PyRuntimeError::new_err("the video stream failed earlier"))
    }
}

fn frames_out(
    py: Python<'_>,
    out: Vec<(VideoFrame, FrameResult)>,
    layout: Layout,
) -> PyResult<Vec<Frame>> {
    out.into_iter()
        .map(|(frame, result)| {
            let image = match frame {
                VideoFrame::Image(img) => to_array(py, img, layout)?,
                // Only images are pushed, and the processor hands each frame back as it came.
                _ => return Err(PyRuntimeError::new_err("unexpected YUV frame")),
            };
            Ok(Frame {
                image: image.unbind(),
                result,
            })
        })
        .collect()
}

#[pymethods]
impl VideoCorrector {
    #[new]
    #[pyo3(signature = (
        *,
        fps = 25.0,
        smoothing_lag = unshear::video::DEFAULT_SMOOTHING_LAG,
        redetect = None,
        lost_interval = 5,
        detect_width = 640,
        hold = 0.5,
        decay = 1.0,
        k_source = "filtered",
        readout = "rows",
        interp = "linear",
        readout_fraction = None,
        motion = true,
        vertical = false,
        deblur_exposure = None,
        correct = true,
        bgr = false,
        max_pixels = DEFAULT_MAX_PIXELS,
        **config
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        #[pyo3(from_py_with = args::fps)] fps: f64,
        #[pyo3(from_py_with = args::smoothing_lag)] smoothing_lag: usize,
        #[pyo3(from_py_with = args::redetect)] redetect: Option<u64>,
        #[pyo3(from_py_with = args::lost_interval)] lost_interval: u64,
        #[pyo3(from_py_with = args::detect_width)] detect_width: u32,
        #[pyo3(from_py_with = args::hold)] hold: f64,
        #[pyo3(from_py_with = args::decay)] decay: f64,
        k_source: &str,
        readout: &str,
        interp: &str,
        #[pyo3(from_py_with = args::readout_fraction)] readout_fraction: Option<f64>,
        motion: bool,
        vertical: bool,
        #[pyo3(from_py_with = args::deblur_exposure)] deblur_exposure: Option<
            unshear::video::Deblur,
        >,
        correct: bool,
        bgr: bool,
        #[pyo3(from_py_with = args::max_pixels)] max_pixels: u64,
        config: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        // The numbers were checked as they were taken (`args`).
        let k_source = match k_source {
            "filtered" => KSource::Filtered,
            "raw" => KSource::Raw,
            other => {
                return Err(bad(format!(
                    "k_source must be \"filtered\" or \"raw\", got {other:?}"
                )))
            }
        };
        let readout = match readout {
            "rows" => Readout::Rows,
            "columns" => Readout::Columns,
            other => {
                return Err(bad(format!(
                    "readout must be \"rows\" or \"columns\", got {other:?}"
                )))
            }
        };
        let interpolation = interp_of(interp)?;
        let cfg = PyConfig::from_kwargs("VideoCorrector", config)?;
        let unshear = py.detach(|| build(&cfg, Use::Video)).map_err(to_pyerr)?;
        let options = ProcessOptions {
            tracker: TrackerParams {
                redetect_interval: redetect.unwrap_or(
                    TrackerParams::for_detector(unshear.uses_network_detector()).redetect_interval,
                ),
                lost_interval,
                detect_width,
                ..Default::default()
            },
            filter: FilterParams::default().with_times(hold, decay, fps),
            smoothing_lag,
            correct,
            k_source,
            interpolation,
            network_budget: unshear.config().network_budget,
            // Frames come as the caller has them (OpenCV turns a rotated clip's upright).
            rotation: 0,
            readout,
            readout_fraction,
            motion,
            vertical,
            deblur: deblur_exposure,
            ..ProcessOptions::default()
        };
        let stream = Stream::new(unshear, |u| VideoProcessor::new(u, options));
        Ok(Self {
            state: Mutex::new(State {
                stream,
                shape: None,
                finished: false,
                phase: Phase::Fresh,
            }),
            bgr,
            max_pixels,
            smoothing_lag,
        })
    }

    /// Frames pushed and not returned yet (at most ``smoothing_lag``).
    #[getter]
    fn pending(&self, py: Python<'_>) -> PyResult<usize> {
        py.detach(|| Ok(self.lock()?.stream.borrow_dependent().pending()))
    }

    /// Frames held back by the smoother: each frame comes out this many pushes later.
    #[getter]
    fn smoothing_lag(&self) -> usize {
        self.smoothing_lag
    }

    /// Takes the next frame; returns the frame now due (``smoothing_lag`` frames older),
    /// corrected, as a list of zero or one ``Frame``.
    fn push(&self, py: Python<'_>, frame: &Bound<'_, PyAny>) -> PyResult<Vec<Frame>> {
        let (input, shape) = self.frame_in(py, frame)?;
        let out = py.detach(|| -> PyResult<_> {
            let mut state = self.lock()?;
            state.admit(shape, Phase::Pushing)?;
            state
                .stream
                .with_dependent_mut(|_, p| p.process(VideoFrame::Image(input.image)))
                .map_err(to_pyerr)
        })?;
        frames_out(py, out.into_iter().collect(), shape.layout)
    }

    /// The first of two passes over a clip that can be read twice (a file): analyses the next
    /// frame (faces, motion, the readout's calibration) and keeps its results, not its pixels.
    /// After the last frame, ``end_analysis()``; then the same frames again through
    /// ``replay()``.
    fn analyse(&self, py: Python<'_>, frame: &Bound<'_, PyAny>) -> PyResult<()> {
        let (input, shape) = self.frame_in(py, frame)?;
        py.detach(|| -> PyResult<()> {
            let mut state = self.lock()?;
            state.admit(shape, Phase::Analysing)?;
            state
                .stream
                .with_dependent_mut(|_, p| p.analyse_frame(&VideoFrame::Image(input.image)));
            Ok(())
        })
    }

    /// Ends the first pass: the readout fitted over the whole clip. Returns the readout
    /// fraction the second pass corrects by (``None`` when it could not be found: the frames
    /// are then corrected from their faces).
    fn end_analysis(&self, py: Python<'_>) -> PyResult<Option<f64>> {
        py.detach(|| -> PyResult<_> {
            let mut state = self.lock()?;
            if state.phase != Phase::Analysing || state.finished {
                return Err(bad(
                    "end_analysis() without a first pass: call analyse() on every frame first"
                        .into(),
                ));
            }
            state.phase = Phase::Replaying;
            Ok(state.stream.with_dependent_mut(|_, p| {
                p.end_analysis();
                p.readout_fraction()
            }))
        })
    }

    /// The second pass: the next frame of the clip, in the order analysed, corrected with what
    /// the first pass found.
    fn replay(&self, py: Python<'_>, frame: &Bound<'_, PyAny>) -> PyResult<Frame> {
        let (input, shape) = self.frame_in(py, frame)?;
        let out = py.detach(|| -> PyResult<_> {
            let mut state = self.lock()?;
            state.admit(shape, Phase::Replaying)?;
            state
                .stream
                .with_dependent_mut(|_, p| p.replay(VideoFrame::Image(input.image)))
                .map_err(to_pyerr)
        })?;
        frames_out(py, vec![out], shape.layout)?
            .pop()
            .ok_or_else(|| PyRuntimeError::new_err("no frame"))
    }

    /// Ends the stream: returns every frame still held, corrected with the shears smoothed over
    /// all the frames seen.
    fn finish(&self, py: Python<'_>) -> PyResult<Vec<Frame>> {
        let (out, layout) = py.detach(|| -> PyResult<_> {
            let mut state = self.lock()?;
            // In two passes every frame came out of replay(): nothing is held.
            if state.finished || matches!(state.phase, Phase::Analysing | Phase::Replaying) {
                state.finished = true;
                return Ok((Vec::new(), None));
            }
            state.finished = true;
            let layout = state.shape.map(|s| s.layout);
            let out = state
                .stream
                .with_dependent_mut(|_, p| p.finish())
                .map_err(to_pyerr)?;
            Ok((out, layout))
        })?;
        match layout {
            Some(layout) => frames_out(py, out, layout),
            None => Ok(Vec::new()),
        }
    }
}
