//! NumPy `.npz` archives: a zip of `.npy` arrays (encoded by the `npyz` crate, zipped by
//! `zip`). Written with fast deflate (like `np.savez_compressed`); read whether stored or
//! deflated, so files from `np.savez` and `np.savez_compressed` both load.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read, Write};
use std::path::Path;

use npyz::WriterBuilder;
use zip::write::SimpleFileOptions;

use crate::core::atomic_file::write_atomic;
use crate::core::error::{Error, Result};

/// The element types the project stores.
#[derive(Clone, Debug, PartialEq)]
pub enum ArrayData {
    U8(Vec<u8>),
    F32(Vec<f32>),
    F64(Vec<f64>),
    I64(Vec<i64>),
    /// Strings (NumPy's `<U` unicode dtype, as `np.array(["a", "bc"])` stores them).
    Text(Vec<String>),
}

/// An n-dimensional array in C order.
#[derive(Clone, Debug, PartialEq)]
pub struct Array {
    pub shape: Vec<usize>,
    pub data: ArrayData,
}

impl Array {
    pub fn u8(shape: &[usize], data: Vec<u8>) -> Self {
        Array {
            shape: shape.to_vec(),
            data: ArrayData::U8(data),
        }
    }
    pub fn f32(shape: &[usize], data: Vec<f32>) -> Self {
        Array {
            shape: shape.to_vec(),
            data: ArrayData::F32(data),
        }
    }
    pub fn f64(shape: &[usize], data: Vec<f64>) -> Self {
        Array {
            shape: shape.to_vec(),
            data: ArrayData::F64(data),
        }
    }
    /// A 1-d array of strings.
    pub fn text(data: Vec<String>) -> Self {
        Array {
            shape: vec![data.len()],
            data: ArrayData::Text(data),
        }
    }
    /// A 0-d array holding one number.
    pub fn scalar(v: f64) -> Self {
        Array {
            shape: vec![],
            data: ArrayData::F64(vec![v]),
        }
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        match &self.data {
            ArrayData::U8(v) => v.len(),
            ArrayData::F32(v) => v.len(),
            ArrayData::F64(v) => v.len(),
            ArrayData::I64(v) => v.len(),
            ArrayData::Text(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// NumPy's name of the element type.
    pub fn dtype_name(&self) -> &'static str {
        match self.data {
            ArrayData::U8(_) => "uint8",
            ArrayData::F32(_) => "float32",
            ArrayData::F64(_) => "float64",
            ArrayData::I64(_) => "int64",
            ArrayData::Text(_) => "unicode text",
        }
    }

    /// Values as f64 (any numeric type; none for text).
    pub fn to_f64(&self) -> Vec<f64> {
        match &self.data {
            ArrayData::U8(v) => v.iter().map(|&x| x as f64).collect(),
            ArrayData::F32(v) => v.iter().map(|&x| x as f64).collect(),
            ArrayData::F64(v) => v.clone(),
            ArrayData::I64(v) => v.iter().map(|&x| x as f64).collect(),
            ArrayData::Text(_) => Vec::new(),
        }
    }
}

/// `.npy` bytes of strings, as NumPy's `<U{longest}` dtype.
fn encode_text(shape: &[usize], data: &[String]) -> std::io::Result<Vec<u8>> {
    let shape: Vec<u64> = shape.iter().map(|&s| s as u64).collect();
    let longest = data
        .iter()
        .map(|s| s.chars().count())
        .max()
        .unwrap_or(0)
        .max(1);
    let dtype = npyz::DType::Plain(
        format!("<U{longest}")
            .parse::<npyz::TypeStr>()
            .map_err(|e| std::io::Error::other(e.to_string()))?,
    );
    let mut buf = Vec::new();
    let mut w = npyz::WriteOptions::<String>::new()
        .dtype(dtype)
        .shape(&shape)
        .writer(&mut buf)
        .begin_nd()?;
    w.extend(data.iter().cloned())?;
    w.finish()?;
    Ok(buf)
}

/// Stream one array as `.npy` into `out` in pieces of [`WRITE_PIECE`] elements, asking for
/// Ctrl-C between them: a big dataset takes seconds to compress, and no copy of it is made.
fn encode<T: npyz::AutoSerialize + Copy>(
    out: &mut impl Write,
    shape: &[usize],
    data: &[T],
    path: &Path,
) -> Result<()> {
    let io = |e: std::io::Error| Error::io(path, e);
    let shape: Vec<u64> = shape.iter().map(|&s| s as u64).collect();
    // npyz writes element by element: buffered, the compressor sees large blocks.
    let mut out = std::io::BufWriter::with_capacity(1 << 20, out);
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&shape)
        .writer(&mut out)
        .begin_nd()
        .map_err(io)?;
    for piece in data.chunks(WRITE_PIECE) {
        crate::core::interrupt::check(|| {
            format!(
                "stopped while writing {}; nothing was written",
                path.display()
            )
        })?;
        w.extend(piece.iter().copied()).map_err(io)?;
    }
    w.finish().map_err(io)?;
    out.flush().map_err(io)
}

/// Elements written between two looks at Ctrl-C (a few hundredths of a second).
const WRITE_PIECE: usize = 1 << 20;

/// An array to write, its elements borrowed (a dataset's gigabyte of images is written
/// without a copy).
pub struct ArrayView<'a> {
    pub shape: Vec<usize>,
    pub data: DataView<'a>,
}

/// [`ArrayData`], borrowed.
pub enum DataView<'a> {
    U8(&'a [u8]),
    F32(&'a [f32]),
    F64(&'a [f64]),
    I64(&'a [i64]),
    Text(&'a [String]),
}

impl<'a> From<&'a Array> for ArrayView<'a> {
    fn from(a: &'a Array) -> Self {
        let data = match &a.data {
            ArrayData::U8(v) => DataView::U8(v),
            ArrayData::F32(v) => DataView::F32(v),
            ArrayData::F64(v) => DataView::F64(v),
            ArrayData::I64(v) => DataView::I64(v),
            ArrayData::Text(v) => DataView::Text(v),
        };
        ArrayView {
            shape: a.shape.clone(),
            data,
        }
    }
}

impl ArrayView<'_> {
    fn len(&self) -> usize {
        match &self.data {
            DataView::U8(v) => v.len(),
            DataView::F32(v) => v.len(),
            DataView::F64(v) => v.len(),
            DataView::I64(v) => v.len(),
            DataView::Text(v) => v.len(),
        }
    }
}

/// Write `arrays` to `path` atomically (no partial file on error or Ctrl-C).
pub fn write_npz(path: &Path, arrays: &[(&str, &Array)]) -> Result<()> {
    let views: Vec<(&str, ArrayView)> = arrays.iter().map(|(n, a)| (*n, (*a).into())).collect();
    write_npz_views(path, &views)
}

/// [`write_npz`] of borrowed arrays.
pub fn write_npz_views(path: &Path, arrays: &[(&str, ArrayView)]) -> Result<()> {
    let io = |e: std::io::Error| Error::io(path, e);
    let zipe = |e: zip::result::ZipError| Error::data(path, format!("cannot write zip: {e}"));
    write_atomic(path, |w| {
        let mut zip = zip::ZipWriter::new(w);
        let opts = SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated)
            .compression_level(Some(1))
            .large_file(true);
        for (name, array) in arrays {
            assert_eq!(
                array.len(),
                array.shape.iter().product::<usize>(),
                "array \"{name}\": data length does not match its shape"
            );
            zip.start_file(format!("{name}.npy"), opts).map_err(zipe)?;
            match array.data {
                DataView::U8(v) => encode(&mut zip, &array.shape, v, path)?,
                DataView::F32(v) => encode(&mut zip, &array.shape, v, path)?,
                DataView::F64(v) => encode(&mut zip, &array.shape, v, path)?,
                DataView::I64(v) => encode(&mut zip, &array.shape, v, path)?,
                DataView::Text(v) => {
                    let bytes = encode_text(&array.shape, v).map_err(io)?;
                    zip.write_all(&bytes).map_err(io)?;
                }
            }
        }
        zip.finish().map_err(zipe)?;
        Ok(())
    })
}

/// The most an `.npz` may decompress to (every member together): 8 GiB, what a dataset may
/// hold in memory.
pub const MAX_NPZ_BYTES: u64 = 8 << 30;

/// The buffer a member starts with, whatever size it claims (it grows as bytes arrive).
const INITIAL_CAPACITY: u64 = 64 << 20;

/// Read every array of an `.npz` file, by key (the member name without `.npy`).
pub fn read_npz(path: &Path) -> Result<BTreeMap<String, Array>> {
    let max = crate::core::input_file::MAX_TABLE_BYTES;
    crate::core::input_file::check_user_file(path, ".npz file", max)?;
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut zip = zip::ZipArchive::new(BufReader::new(file))
        .map_err(|e| Error::data(path, format!("not an .npz file (bad zip: {e})")))?;
    let mut out = BTreeMap::new();
    let mut total: u64 = 0;
    for i in 0..zip.len() {
        let mut member = zip
            .by_index(i)
            .map_err(|e| Error::data(path, format!("corrupt .npz member {i}: {e}")))?;
        let name = member
            .name()
            .map_err(|e| Error::data(path, format!("corrupt .npz member {i}: {e}")))?
            .to_string();
        let key = name.strip_suffix(".npy").unwrap_or(&name).to_string();
        // The size a member claims is not trusted: the buffer starts small, grows with the
        // bytes that really arrive, and decompression stops past the limit (a zip bomb).
        let room = MAX_NPZ_BYTES.saturating_sub(total);
        let mut bytes = Vec::with_capacity(member.size().min(INITIAL_CAPACITY) as usize);
        (&mut member)
            .take(room + 1)
            .read_to_end(&mut bytes)
            .map_err(|e| Error::data(path, format!("corrupt .npz member \"{name}\": {e}")))?;
        if bytes.len() as u64 > room {
            return Err(Error::data(
                path,
                format!(
                    "\"{key}\" decompresses to more than the {} GiB an .npz may hold here (a damaged or hostile file)",
                    MAX_NPZ_BYTES >> 30
                ),
            ));
        }
        total += bytes.len() as u64;
        let bad = |e: std::io::Error| {
            Error::data(path, format!("\"{key}\" is not a valid .npy array: {e}"))
        };
        let npy = npyz::NpyFile::new(&bytes[..]).map_err(bad)?;
        let shape: Vec<usize> = npy.shape().iter().map(|&s| s as usize).collect();
        // A damaged or forged header can claim more elements than the member holds (or than
        // the count can hold): every element takes at least a byte.
        let fits = npy
            .shape()
            .iter()
            .try_fold(1u64, |n, &d| n.checked_mul(d))
            .is_some_and(|n| n <= bytes.len() as u64);
        if !fits {
            return Err(Error::data(
                path,
                format!(
                    "\"{key}\": its header claims shape {:?}, more elements than the file holds",
                    npy.shape()
                ),
            ));
        }
        if npy.order() != npyz::Order::C {
            return Err(Error::data(
                path,
                format!("\"{key}\" is stored in Fortran order; save it C-contiguous"),
            ));
        }
        let descr = npy.dtype().descr().trim_matches('\'').to_string();
        let data = match descr.as_str() {
            "|u1" | "<u1" => ArrayData::U8(npy.into_vec().map_err(bad)?),
            "<f4" => ArrayData::F32(npy.into_vec().map_err(bad)?),
            "<f8" => ArrayData::F64(npy.into_vec().map_err(bad)?),
            "<i8" => ArrayData::I64(npy.into_vec().map_err(bad)?),
            d if d.starts_with("<U") => ArrayData::Text(npy.into_vec().map_err(bad)?),
            "<i4" => ArrayData::I64(
                npy.into_vec::<i32>()
                    .map_err(bad)?
                    .into_iter()
                    .map(i64::from)
                    .collect(),
            ),
            other => {
                return Err(Error::data(
                    path,
                    format!(
                        "\"{key}\" has dtype {other}; expected uint8, float32, float64, int32, int64 or unicode text"
                    ),
                ));
            }
        };
        out.insert(key, Array { shape, data });
    }
    Ok(out)
}
