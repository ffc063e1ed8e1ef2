//! numpy arrays in and out: checked, copied into owned image buffers (so any strides, read-only
//! and non-contiguous arrays work, and Rust never reads Python's memory without the GIL), and
//! back in the caller's layout.

use image::{DynamicImage, ImageBuffer, Luma, LumaA, Pixel, Rgb, Rgba};
use numpy::ndarray::{Array, IxDyn};
use numpy::{
    Element, PyArray, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyModule;

/// How an array was laid out, so that results come back the same way.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// A 2-D array (grey, H x W), rather than H x W x C.
    pub two_d: bool,
    /// Channels 0 and 2 swapped (OpenCV's BGR / BGRA).
    pub bgr: bool,
}

/// An image taken from Python, and how to hand results back.
#[derive(Debug, Clone)]
pub struct Input {
    pub image: DynamicImage,
    pub layout: Layout,
}

fn numpy(py: Python<'_>) -> PyResult<&Bound<'_, PyModule>> {
    static NUMPY: PyOnceLock<Py<PyModule>> = PyOnceLock::new();
    NUMPY
        .get_or_try_init(py, || PyModule::import(py, "numpy").map(Bound::unbind))
        .map(|m| m.bind(py))
}

/// The array's elements in row-major order: directly when it is C-contiguous, aligned and in
/// the machine's byte order, otherwise through `numpy.ascontiguousarray` (one C-level copy).
fn elements<T: Element + Copy>(
    py: Python<'_>,
    obj: &Bound<'_, PyAny>,
    dtype: &str,
) -> PyResult<Vec<T>> {
    if let Ok(array) = obj.cast::<PyArrayDyn<T>>() {
        if array.is_c_contiguous() {
            let view = array
                .try_readonly()
                .map_err(|e| PyValueError::new_err(format!("the array cannot be read: {e}")))?;
            if let Ok(slice) = view.as_slice() {
                return Ok(slice.to_vec());
            }
        }
    }
    let np = numpy(py)?;
    let copy = np.call_method1("ascontiguousarray", (obj, np.getattr(dtype)?))?;
    let array = copy.cast_into::<PyArrayDyn<T>>().map_err(PyErr::from)?;
    let view = array
        .try_readonly()
        .map_err(|e| PyValueError::new_err(format!("the array cannot be read: {e}")))?;
    let slice = view
        .as_slice()
        .map_err(|e| PyValueError::new_err(format!("the array cannot be read: {e}")))?;
    Ok(slice.to_vec())
}

fn buffer<P: Pixel>(
    w: u32,
    h: u32,
    data: Vec<P::Subpixel>,
) -> PyResult<ImageBuffer<P, Vec<P::Subpixel>>> {
    ImageBuffer::from_raw(w, h, data)
        .ok_or_else(|| PyValueError::new_err("the array's size does not match its shape"))
}

fn swap_red_blue<T>(data: &mut [T], channels: usize) {
    if channels >= 3 {
        for px in data.chunks_exact_mut(channels) {
            px.swap(0, 2);
        }
    }
}

/// Checks `obj` (a numpy `uint8` or `uint16` array, H x W or H x W x C with C = 1, 2, 3 or 4,
/// at most `max_pixels` pixels) and copies it into an image; `bgr` swaps the first and third
/// channels of colour images. Every refusal is a `ValueError` (`TypeError` for a non-array),
/// raised before any pixel is copied.
pub fn from_array(
    py: Python<'_>,
    obj: &Bound<'_, PyAny>,
    bgr: bool,
    max_pixels: u64,
) -> PyResult<Input> {
    let array = obj.cast::<PyUntypedArray>().map_err(|_| {
        PyTypeError::new_err(format!(
            "expected a numpy array (H x W or H x W x C, uint8 or uint16), got {}",
            obj.get_type()
                .name()
                .map_or_else(|_| "?".to_string(), |n| n.to_string())
        ))
    })?;
    let shape = array.shape().to_vec();
    let (h, w, c, two_d) = match *shape.as_slice() {
        [h, w] => (h, w, 1, true),
        [h, w, c] => (h, w, c, false),
        _ => {
            return Err(PyValueError::new_err(format!(
                "expected an H x W or H x W x C image array, got shape {shape:?}"
            )))
        }
    };
    if !(1..=4).contains(&c) {
        return Err(PyValueError::new_err(format!(
            "expected 1, 2, 3 or 4 channels (grey, grey+alpha, RGB, RGBA), got shape {shape:?}"
        )));
    }
    if h == 0 || w == 0 {
        return Err(PyValueError::new_err(format!(
            "the image is empty (shape {shape:?})"
        )));
    }
    let pixels = (h as u64).saturating_mul(w as u64);
    let (Ok(w32), Ok(h32)) = (u32::try_from(w), u32::try_from(h)) else {
        return Err(PyValueError::new_err(format!(
            "image is {w}x{h} pixels, over the limit of {max_pixels} pixels"
        )));
    };
    if pixels > max_pixels {
        return Err(PyValueError::new_err(format!(
            "image is {w}x{h} = {pixels} pixels, over the limit of {max_pixels} pixels"
        )));
    }
    let dtype = array.dtype();
    let (kind, size) = (dtype.kind(), dtype.itemsize());
    let swap = bgr && c >= 3;
    let image = match (kind, size) {
        (b'u', 1) => {
            let mut data: Vec<u8> = elements(py, obj, "uint8")?;
            if swap {
                swap_red_blue(&mut data, c);
            }
            match c {
                1 => DynamicImage::ImageLuma8(buffer::<Luma<u8>>(w32, h32, data)?),
                2 => DynamicImage::ImageLumaA8(buffer::<LumaA<u8>>(w32, h32, data)?),
                3 => DynamicImage::ImageRgb8(buffer::<Rgb<u8>>(w32, h32, data)?),
                _ => DynamicImage::ImageRgba8(buffer::<Rgba<u8>>(w32, h32, data)?),
            }
        }
        (b'u', 2) => {
            let mut data: Vec<u16> = elements(py, obj, "uint16")?;
            if swap {
                swap_red_blue(&mut data, c);
            }
            match c {
                1 => DynamicImage::ImageLuma16(buffer::<Luma<u16>>(w32, h32, data)?),
                2 => DynamicImage::ImageLumaA16(buffer::<LumaA<u16>>(w32, h32, data)?),
                3 => DynamicImage::ImageRgb16(buffer::<Rgb<u16>>(w32, h32, data)?),
                _ => DynamicImage::ImageRgba16(buffer::<Rgba<u16>>(w32, h32, data)?),
            }
        }
        _ => {
            let name = dtype
                .str()
                .map_or_else(|_| "?".to_string(), |s| s.to_string());
            return Err(PyValueError::new_err(format!(
                "expected a uint8 or uint16 array, got dtype {name} (convert with .astype(numpy.uint8))"
            )));
        }
    };
    Ok(Input {
        image,
        layout: Layout { two_d, bgr: swap },
    })
}

fn out<'py, T: Element>(
    py: Python<'py>,
    mut data: Vec<T>,
    h: u32,
    w: u32,
    channels: usize,
    layout: Layout,
) -> PyResult<Bound<'py, PyAny>> {
    if layout.bgr {
        swap_red_blue(&mut data, channels);
    }
    let (h, w) = (h as usize, w as usize);
    let shape: Vec<usize> = if channels == 1 && layout.two_d {
        vec![h, w]
    } else {
        vec![h, w, channels]
    };
    let array = Array::from_shape_vec(IxDyn(&shape), data)
        .map_err(|e| PyValueError::new_err(format!("image buffer: {e}")))?;
    Ok(PyArray::from_owned_array(py, array).into_any())
}

/// The image as a new numpy array (no copy of the pixels: numpy takes the buffer): H x W for a
/// grey image when `layout.two_d`, H x W x C otherwise; `uint8`, or `uint16` for 16-bit images
/// (32-bit float images, which only some TIFFs decode to, become `uint16`).
pub fn to_array(py: Python<'_>, image: DynamicImage, layout: Layout) -> PyResult<Bound<'_, PyAny>> {
    let (w, h) = (image.width(), image.height());
    match image {
        DynamicImage::ImageLuma8(b) => out(py, b.into_raw(), h, w, 1, layout),
        DynamicImage::ImageLumaA8(b) => out(py, b.into_raw(), h, w, 2, layout),
        DynamicImage::ImageRgb8(b) => out(py, b.into_raw(), h, w, 3, layout),
        DynamicImage::ImageRgba8(b) => out(py, b.into_raw(), h, w, 4, layout),
        DynamicImage::ImageLuma16(b) => out(py, b.into_raw(), h, w, 1, layout),
        DynamicImage::ImageLumaA16(b) => out(py, b.into_raw(), h, w, 2, layout),
        DynamicImage::ImageRgb16(b) => out(py, b.into_raw(), h, w, 3, layout),
        DynamicImage::ImageRgba16(b) => out(py, b.into_raw(), h, w, 4, layout),
        DynamicImage::ImageRgb32F(_) => out(py, image.to_rgb16().into_raw(), h, w, 3, layout),
        other => out(py, other.to_rgba16().into_raw(), h, w, 4, layout),
    }
}
