//! Scans from NumPy: every check a scan file gets, on an array, and its
//! samples read in place (no copy) while the array is borrowed.

use dmap::npy::{ScanDtype, ScanFile};
use numpy::{
    Element, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// An array's samples, borrowed read-only for as long as this lives
/// (`Other`: an array in the other byte order, or unaligned, held, its
/// buffer read in place as bytes).
pub enum Held<'py> {
    Other(Bound<'py, PyUntypedArray>),
    U8(PyReadonlyArrayDyn<'py, u8>),
    U16(PyReadonlyArrayDyn<'py, u16>),
    U32(PyReadonlyArrayDyn<'py, u32>),
    F32(PyReadonlyArrayDyn<'py, f32>),
    F64(PyReadonlyArrayDyn<'py, f64>),
}

/// A scan array, checked and borrowed.
pub struct ScanArray<'py> {
    /// What messages call it (`scan`, `scans[2]`).
    pub name: String,
    pub shape: Vec<usize>,
    pub dtype: ScanDtype,
    pub big_endian: bool,
    held: Held<'py>,
}

fn bytes_of<'a, T: Element>(a: &'a PyReadonlyArrayDyn<'_, T>) -> &'a [u8] {
    let s = a.as_slice().expect("checked C-contiguous");
    // SAFETY: plain integers and floats, no padding; the length is the
    // slice's in bytes.
    unsafe { std::slice::from_raw_parts(s.as_ptr().cast::<u8>(), std::mem::size_of_val(s)) }
}

fn borrow<'py, T: Element>(
    obj: &Bound<'py, PyAny>,
    name: &str,
) -> PyResult<PyReadonlyArrayDyn<'py, T>> {
    let a = obj
        .cast::<PyArrayDyn<T>>()
        .map_err(|_| PyValueError::new_err(format!("{name}: the array's dtype changed")))?;
    a.try_readonly()
        .map_err(|e| PyValueError::new_err(format!("{name}: the array is being written: {e}")))
}

impl<'py> ScanArray<'py> {
    /// Checks `obj` as a scan (rank 4; a dtype a scan file may have, in
    /// the machine's byte order; C-contiguous) and borrows it.
    pub fn new(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Self> {
        let arr = obj.cast::<PyUntypedArray>().map_err(|_| {
            PyValueError::new_err(format!(
                "{name}: not a NumPy array but {} (a scan is an array (rows, cols, J1, J2))",
                obj.get_type().name().map_or("?".into(), |n| n.to_string())
            ))
        })?;
        let shape = arr.shape().to_vec();
        if shape.len() != 4 {
            return Err(PyValueError::new_err(format!(
                "{name}: a scan must have rank 4 (rows, cols, J1, J2), got shape {shape:?} (rank {})",
                shape.len()
            )));
        }
        let dt = arr.dtype();
        let dtype = match (dt.kind(), dt.itemsize()) {
            (b'u', 1) => ScanDtype::U8,
            (b'u', 2) => ScanDtype::U16,
            (b'u', 4) => ScanDtype::U32,
            (b'f', 4) => ScanDtype::F32,
            (b'f', 8) => ScanDtype::F64,
            _ => {
                return Err(PyValueError::new_err(format!(
                    "{name}: unsupported dtype {} (scans must be uint8, uint16, uint32, float32 or float64)",
                    dt.str().map_or("?".into(), |s| s.to_string())
                )));
            }
        };
        let native = dt.is_native_byteorder() != Some(false);
        if !arr.is_c_contiguous() {
            return Err(PyValueError::new_err(format!(
                "{name}: the array is not C-contiguous (a view with strides): pass numpy.ascontiguousarray({name}), which copies it once"
            )));
        }
        // SAFETY: the array object's own flags, read while it is held.
        let flags = unsafe { (*arr.as_array_ptr()).fields.flags };
        let aligned = flags & numpy::npyffi::NPY_ARRAY_ALIGNED != 0;
        let held = match dtype {
            // Read as bytes: no typed slice over unaligned samples.
            _ if !native || !aligned => Held::Other(arr.clone()),
            ScanDtype::U8 => Held::U8(borrow(obj, name)?),
            ScanDtype::U16 => Held::U16(borrow(obj, name)?),
            ScanDtype::U32 => Held::U32(borrow(obj, name)?),
            ScanDtype::F32 => Held::F32(borrow(obj, name)?),
            ScanDtype::F64 => Held::F64(borrow(obj, name)?),
        };
        Ok(ScanArray {
            name: name.to_string(),
            shape,
            dtype,
            big_endian: cfg!(target_endian = "big") == native,
            held,
        })
    }

    /// The samples' bytes, in place.
    pub fn bytes(&self) -> &[u8] {
        match &self.held {
            Held::Other(a) => {
                let len = a.len() * self.dtype.item();
                if len == 0 {
                    return &[];
                }
                // SAFETY: a C-contiguous array (checked) of `len` bytes
                // from its data pointer, alive while `a` is held.
                unsafe {
                    std::slice::from_raw_parts((*a.as_array_ptr()).fields.data.cast::<u8>(), len)
                }
            }
            Held::U8(a) => bytes_of(a),
            Held::U16(a) => bytes_of(a),
            Held::U32(a) => bytes_of(a),
            Held::F32(a) => bytes_of(a),
            Held::F64(a) => bytes_of(a),
        }
    }

    /// What the GIL-free side needs: the name, the bytes, the shape, the dtype.
    pub fn view(&self) -> View<'_> {
        View {
            name: &self.name,
            bytes: self.bytes(),
            shape: &self.shape,
            dtype: self.dtype,
            big_endian: self.big_endian,
        }
    }
}

/// A borrowed scan's samples, free of the interpreter (it may cross to
/// other threads while the GIL is released).
#[derive(Clone, Copy)]
pub struct View<'a> {
    pub name: &'a str,
    pub bytes: &'a [u8],
    pub shape: &'a [usize],
    pub dtype: ScanDtype,
    pub big_endian: bool,
}

impl<'a> View<'a> {
    /// The scan as `dmap` reads a file: shape checks first.
    pub fn open(&self) -> anyhow::Result<ScanFile<'a>> {
        ScanFile::from_bytes(
            self.name,
            self.bytes,
            self.shape,
            (self.dtype, self.big_endian),
        )
    }

    /// Rows and columns (the shape is rank 4, checked).
    pub fn positions(&self) -> (usize, usize) {
        (self.shape[0], self.shape[1])
    }
}
