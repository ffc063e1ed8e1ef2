//! What `estimate` finds, as Python objects: `Face` and `Report` (and `Frame` for video), with
//! the CLI's `--json` field names.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyType};
use serde::de::DeserializeOwned;
use serde::Serialize;

use unshear::{FaceReport, ImageReport, Point, Readout};

type Pair = (f64, f64);

fn pair(p: Point) -> Pair {
    (p.x, p.y)
}

/// A result's whole state as plain Python objects (dicts, lists, floats, strings), for pickling.
pub fn state<'py, T: Serialize>(py: Python<'py>, value: &T) -> PyResult<Bound<'py, PyAny>> {
    pythonize::pythonize(py, value).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// What `__reduce__` returns for a result pickled by its state: its class's `_from_state`
/// and the state.
pub type Reduced<'py> = (Bound<'py, PyAny>, (Bound<'py, PyAny>,));

/// `__reduce__` of the result `slf`, whose state is `value`.
fn reduce<'py, T: pyo3::PyClass, S: Serialize>(
    slf: &Bound<'py, T>,
    value: &S,
) -> PyResult<Reduced<'py>> {
    let restore = slf.as_any().get_type().getattr("_from_state")?;
    Ok((restore, (state(slf.py(), value)?,)))
}

/// A result back from [`state`]'s objects.
pub fn from_state<T: DeserializeOwned>(state: &Bound<'_, PyAny>) -> PyResult<T> {
    pythonize::depythonize(state)
        .map_err(|e| PyValueError::new_err(format!("not the state of an unshear result: {e}")))
}

fn point_list<'py>(py: Python<'py>, p: Option<Point>) -> PyResult<Option<Bound<'py, PyList>>> {
    p.map(|p| PyList::new(py, [p.x, p.y])).transpose()
}

/// One face: where it is, its landmarks and its shear. Points are ``(x, y)`` in the input's
/// pixels, origin top left; the subject's right eye is on the image's left.
#[pyclass(module = "unshear", frozen, eq)]
#[derive(Debug, Clone, PartialEq)]
pub struct Face {
    pub inner: FaceReport,
}

#[pymethods]
impl Face {
    /// The face box ``(x, y, width, height)``.
    #[getter(r#box)]
    fn face_box(&self) -> (f64, f64, f64, f64) {
        let b = self.inner.face_box;
        (b.x, b.y, b.width, b.height)
    }

    /// The subject's right eye (on the image's left).
    #[getter]
    fn right_eye(&self) -> Pair {
        pair(self.inner.right_eye)
    }

    /// The subject's left eye (on the image's right).
    #[getter]
    fn left_eye(&self) -> Pair {
        pair(self.inner.left_eye)
    }

    /// The subject's right nostril.
    #[getter]
    fn right_nostril(&self) -> Pair {
        pair(self.inner.right_nostril)
    }

    /// The subject's left nostril.
    #[getter]
    fn left_nostril(&self) -> Pair {
        pair(self.inner.left_nostril)
    }

    /// The nose point (the lower nose), or ``None`` when the locator gives none.
    #[getter]
    fn nose(&self) -> Option<Pair> {
        self.inner.nose_tip.map(pair)
    }

    /// The mouth centre, or ``None``.
    #[getter]
    fn mouth(&self) -> Option<Pair> {
        self.inner.mouth.map(pair)
    }

    /// The shear of this face, or ``None`` when the estimate was refused (confidence below
    /// ``min_confidence``).
    #[getter]
    fn k(&self) -> Option<f64> {
        self.inner.k
    }

    /// The shear measured, refused or not.
    #[getter]
    fn k_measured(&self) -> f64 {
        self.inner.k_measured
    }

    /// The head's roll in degrees (positive: the subject's left eye, on the image's right, lower).
    #[getter]
    fn roll(&self) -> f64 {
        self.inner.roll_degrees
    }

    /// The chance (0 to 1) that the estimate is within 0.10 of the true shear.
    #[getter]
    fn confidence(&self) -> f64 {
        self.inner.confidence
    }

    /// The landmark network's face score (0 to 1), or ``None`` with ``locator="filters"``.
    #[getter]
    fn face_score(&self) -> Option<f64> {
        self.inner.face_score
    }

    /// Why ``k`` is ``None`` (``"low_confidence"``, ``"implausible_shear"``, ...), or ``None``.
    #[getter]
    fn refused(&self) -> Option<&'static str> {
        self.inner.refused.map(|r| r.name())
    }

    /// Whether the image's shear came from other faces that disagree with this one's.
    #[getter]
    fn outvoted(&self) -> bool {
        self.inner.outvoted
    }

    /// The face as a dict with the CLI's ``--json`` keys (points as ``[x, y]`` lists, not
    /// rounded).
    pub(crate) fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let f = &self.inner;
        let d = PyDict::new(py);
        let b = f.face_box;
        d.set_item("box", PyList::new(py, [b.x, b.y, b.width, b.height])?)?;
        d.set_item("right_eye", point_list(py, Some(f.right_eye))?)?;
        d.set_item("left_eye", point_list(py, Some(f.left_eye))?)?;
        d.set_item("right_nostril", point_list(py, Some(f.right_nostril))?)?;
        d.set_item("left_nostril", point_list(py, Some(f.left_nostril))?)?;
        d.set_item("nose", point_list(py, f.nose_tip)?)?;
        d.set_item("mouth", point_list(py, f.mouth)?)?;
        d.set_item("k", f.k)?;
        d.set_item("k_measured", f.k_measured)?;
        d.set_item("roll", f.roll_degrees)?;
        d.set_item("confidence", f.confidence)?;
        d.set_item("refused", f.refused.map(|r| r.name()))?;
        d.set_item("outvoted", f.outvoted)?;
        Ok(d)
    }

    /// Pickles as the face's full state (`copy` and `multiprocessing` use the same).
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Reduced<'py>> {
        reduce(slf, &slf.get().inner)
    }

    #[classmethod]
    fn _from_state(_cls: &Bound<'_, PyType>, state: &Bound<'_, PyAny>) -> PyResult<Self> {
        Ok(Self {
            inner: from_state(state)?,
        })
    }

    fn __repr__(&self) -> String {
        let b = self.inner.face_box;
        format!(
            "Face(box=({:.1}, {:.1}, {:.1}, {:.1}), k={}, k_measured={:.4}, roll={:.2}, confidence={:.3})",
            b.x,
            b.y,
            b.width,
            b.height,
            self.inner.k.map_or("None".to_string(), |k| format!("{k:.4}")),
            self.inner.k_measured,
            self.inner.roll_degrees,
            self.inner.confidence
        )
    }
}

/// What was found in one image: its shear ``k`` (the confidence-weighted median of its faces'
/// accepted estimates, ``None`` without one) and every face.
#[pyclass(module = "unshear", frozen, eq)]
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    pub inner: ImageReport,
}

#[pymethods]
impl Report {
    /// The image's shear, or ``None`` when no face gave an accepted estimate.
    #[getter]
    fn k(&self) -> Option<f64> {
        self.inner.k
    }

    /// Every face found, with its estimate.
    #[getter]
    fn faces(&self) -> Vec<Face> {
        faces(&self.inner.faces)
    }

    /// The image's width in pixels.
    #[getter]
    fn width(&self) -> u32 {
        self.inner.width
    }

    /// The image's height in pixels.
    #[getter]
    fn height(&self) -> u32 {
        self.inner.height
    }

    /// Whether the faces' estimates disagree with no consistent majority (``k`` is then
    /// ``None``).
    #[getter]
    fn faces_disagree(&self) -> bool {
        self.inner.faces_disagree
    }

    /// ``"rows"``, or ``"columns"`` for a photo its EXIF orientation turns a quarter (a phone
    /// held upright), read out column by column: its ``k`` is the vertical shear
    /// ``y' = y + k x`` (``correct`` undoes it so).
    #[getter]
    fn readout(&self) -> &'static str {
        match self.inner.readout {
            Readout::Rows => "rows",
            Readout::Columns => "columns",
        }
    }

    /// Which rulers made ``k``: ``"faces"``, ``"faces+scene"`` or ``"scene"``; ``None`` when
    /// ``k`` is.
    #[getter]
    fn k_source(&self) -> Option<&'static str> {
        self.inner.k_source.map(|s| s.name())
    }

    /// The shear the scene's verticals give (``ruler``), or ``None`` when the scene was not read
    /// or gave none.
    #[getter]
    fn scene_k(&self) -> Option<f64> {
        self.inner.scene.as_ref().map(|s| s.k)
    }

    /// The uncertainty (one standard deviation) of ``scene_k``.
    #[getter]
    fn scene_uncertainty(&self) -> Option<f64> {
        self.inner.scene.as_ref().map(|s| s.uncertainty)
    }

    /// Whether the faces and the scene both gave a shear and these disagree beyond their
    /// uncertainties (the faces made ``k``: the subject moved differently from the camera).
    #[getter]
    fn scene_disagrees(&self) -> bool {
        self.inner.scene_disagrees
    }

    /// ``[(row, k), (row, k)]``: the shear at the highest and the lowest face's row when faces at
    /// different heights disagree beyond their uncertainty (a pan changing speed during the
    /// readout; linear between, held beyond, and ``k`` is its value at the middle row), or
    /// ``None`` (one shear for every row).
    #[getter]
    fn k_rows(&self) -> Option<Vec<(f64, f64)>> {
        self.inner.row_shear.map(|r| vec![r.top, r.bottom])
    }

    /// What the caller should know about this image (views skipped, data missing, ...).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.inner.warnings.clone()
    }

    /// The report as a dict with the CLI's ``--json`` keys (``k``, ``faces``, ...), not rounded.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("k", self.inner.k)?;
        let faces = PyList::empty(py);
        for f in &self.inner.faces {
            faces.append(Face { inner: *f }.to_dict(py)?)?;
        }
        d.set_item("faces", faces)?;
        d.set_item("faces_disagree", self.inner.faces_disagree)?;
        d.set_item("warnings", self.inner.warnings.clone())?;
        if self.inner.readout == Readout::Columns {
            d.set_item("readout", "columns")?;
        }
        // Present only when set, as in the CLI's JSON.
        if let Some(source) = self.k_source() {
            d.set_item("k_source", source)?;
        }
        if let Some(scene) = &self.inner.scene {
            d.set_item("scene_k", scene.k)?;
            d.set_item("scene_uncertainty", scene.uncertainty)?;
        }
        if self.inner.scene_disagrees {
            d.set_item("scene_disagrees", true)?;
        }
        if let Some(r) = self.inner.row_shear {
            d.set_item("k_rows", vec![[r.top.0, r.top.1], [r.bottom.0, r.bottom.1]])?;
        }
        Ok(d)
    }

    /// Pickles as the report's full state (`copy` and `multiprocessing` use the same).
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Reduced<'py>> {
        reduce(slf, &slf.get().inner)
    }

    #[classmethod]
    fn _from_state(_cls: &Bound<'_, PyType>, state: &Bound<'_, PyAny>) -> PyResult<Self> {
        Ok(Self {
            inner: from_state(state)?,
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "Report(k={}, faces={}, width={}, height={})",
            self.inner
                .k
                .map_or("None".to_string(), |k| format!("{k:.4}")),
            self.inner.faces.len(),
            self.inner.width,
            self.inner.height
        )
    }
}

pub fn faces(faces: &[FaceReport]) -> Vec<Face> {
    faces.iter().map(|&inner| Face { inner }).collect()
}
