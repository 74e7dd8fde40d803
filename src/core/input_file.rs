//! Reading what a user hands over (robot descriptions, meshes, the files they name): regular
//! files only, of bounded size, checked before a byte is read (a FIFO would block forever,
//! `/dev/zero` never ends, a sparse file claims gigabytes); and a guard for third-party parsers
//! that panic on damaged input, so a damaged file is one error line, not a crash.

use std::cell::Cell;
use std::io::Read;
use std::path::Path;

/// The largest robot description (URDF) read: far beyond any real one (a humanoid's is
/// ~100 kB).
pub const MAX_DESCRIPTION_BYTES: u64 = 64 << 20;

/// The largest weights file read (a saved model's `model.bpk`; the paper's models are tens of
/// MB).
pub const MAX_WEIGHTS_BYTES: u64 = 4 << 30;

/// The largest table or array file read (`targets`, `angles`, `.npz`): 10 million poses
/// of a humanoid fit.
pub const MAX_TABLE_BYTES: u64 = 8 << 30;

/// The largest JSON file a user's model folder holds (`model.json`).
pub const MAX_JSON_BYTES: u64 = 16 << 20;

/// The largest mesh file read (and any file a mesh names, an OBJ's materials).
pub const MAX_MESH_BYTES: u64 = 512 << 20;

/// The size of `path`, if it is a regular file (a link to one is followed) of at most `max`
/// bytes; otherwise an error saying what it is. `what` names the file in the message
/// ("mesh", "robot description").
fn regular_len(path: &Path, what: &str, max: u64) -> std::io::Result<u64> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        let kind = if meta.is_dir() {
            "a folder"
        } else {
            "not a regular file (a FIFO, socket or device)"
        };
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("the {what} is {kind}: give a file"),
        ));
    }
    if meta.len() > max {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "the {what} is {} MiB, more than the {} MiB read here",
                meta.len() >> 20,
                max >> 20
            ),
        ));
    }
    Ok(meta.len())
}

/// The bytes of `path`, if it is a regular file of at most `max` bytes (see [`regular_len`]).
pub fn read_regular(path: &Path, what: &str, max: u64) -> std::io::Result<Vec<u8>> {
    let len = regular_len(path, what, max)?;
    let mut bytes = Vec::with_capacity(len as usize);
    std::fs::File::open(path)?
        .take(max + 1)
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("the {what} grew past the {} MiB read here", max >> 20),
        ));
    }
    Ok(bytes)
}

/// The deepest nesting of XML elements read (a URDF or SRDF nests 3-4 deep; the parsers
/// recurse, on Python's thread too, whose stack is smaller than a command's).
pub const MAX_XML_NESTING: usize = 100;

/// How deep the XML elements of `text` nest (comments, declarations and processing
/// instructions aside; a rough scan, enough to refuse a file that would exhaust the stack).
fn nesting_depth(text: &str) -> usize {
    let (mut depth, mut deepest) = (0usize, 0usize);
    let bytes = text.as_bytes();
    let mut i = 0;
    while let Some(at) = text[i..].find('<') {
        let start = i + at;
        let Some(len) = text[start..].find('>') else {
            break;
        };
        let end = start + len;
        match bytes.get(start + 1) {
            Some(b'/') => depth = depth.saturating_sub(1),
            Some(b'!' | b'?') => {}
            _ if bytes[end - 1] == b'/' => {}
            _ => {
                depth += 1;
                deepest = deepest.max(depth);
            }
        }
        i = end + 1;
    }
    deepest
}

/// The text outside XML comments.
pub fn without_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(start) = rest.find("<!--") {
        out.push_str(&rest[..start]);
        rest = match rest[start + 4..].find("-->") {
            Some(end) => &rest[start + 4 + end + 3..],
            None => "",
        };
    }
    out.push_str(rest);
    out
}

/// `Err` (one line, for the file's own error) where the XML elements of `text` nest deeper
/// than [`MAX_XML_NESTING`].
pub fn check_xml_depth(text: &str) -> Result<(), String> {
    let depth = nesting_depth(&without_comments(text));
    if depth > MAX_XML_NESTING {
        return Err(format!(
            "its elements nest {depth} deep (a robot's XML nests a few levels; at most {MAX_XML_NESTING} are read)"
        ));
    }
    Ok(())
}

/// The text of an XML file a user names (`what`: "robot description", "SRDF file"), read as
/// [`read_regular`] reads (at most [`MAX_DESCRIPTION_BYTES`]), UTF-8, its byte-order mark
/// dropped. Its nesting is checked by [`check_xml_depth`] where it is parsed.
pub fn read_xml(path: &Path, what: &str) -> crate::core::error::Result<String> {
    read_user_text(path, what, MAX_DESCRIPTION_BYTES, "XML")
}

/// The text of a file a user names in `format` (XML, YAML), read as [`read_regular`] reads
/// (at most `max` bytes), UTF-8, its byte-order mark dropped.
pub fn read_user_text(
    path: &Path,
    what: &str,
    max: u64,
    format: &str,
) -> crate::core::error::Result<String> {
    use crate::core::error::Error;
    let bytes = read_regular(path, what, max).map_err(|e| Error::io(path, e))?;
    let text = String::from_utf8(bytes).map_err(|_| {
        Error::data(
            path,
            format!("the {what} is not UTF-8 text (it is {format}: save it as UTF-8)"),
        )
    })?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// The bytes of a file a user names, as [`read_regular`] reads them, with the path in the
/// error.
pub fn read_user_file(path: &Path, what: &str, max: u64) -> crate::core::error::Result<Vec<u8>> {
    read_regular(path, what, max).map_err(|e| crate::core::error::Error::io(path, e))
}

/// Checks a file a user names before a reader that opens it itself (burn's recorders): a
/// regular file of at most `max` bytes, or the error [`read_regular`] gives.
pub fn check_user_file(path: &Path, what: &str, max: u64) -> crate::core::error::Result<()> {
    regular_len(path, what, max)
        .map(|_| ())
        .map_err(|e| crate::core::error::Error::io(path, e))
}

thread_local! {
    /// Set while [`catch_panic`] runs: the panic hook stays quiet for panics it catches.
    static QUIET: Cell<bool> = const { Cell::new(false) };
}

/// Run `f` (a third-party parser on a user's file), turning a panic inside it into `Err`
/// with its message, printed nowhere: the caller reports it as one line.
pub fn catch_panic<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(Cell::get) {
                previous(info);
            }
        }));
    });
    let was = QUIET.with(|q| q.replace(true));
    let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    QUIET.with(|q| q.set(was));
    out.map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_bounded_regular_files_are_read_and_panics_are_caught() {
        let dir = std::env::temp_dir().join(format!("input-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("a.txt");
        std::fs::write(&file, b"hello").unwrap();
        assert_eq!(read_regular(&file, "test", 5).unwrap(), b"hello");
        let err = read_regular(&file, "test", 4).unwrap_err().to_string();
        assert!(err.contains("more than"), "{err}");
        let err = read_regular(&dir, "test", 4).unwrap_err().to_string();
        assert!(err.contains("a folder"), "{err}");
        #[cfg(unix)]
        {
            let err = read_regular(Path::new("/dev/zero"), "mesh", 4)
                .unwrap_err()
                .to_string();
            assert!(err.contains("not a regular file"), "{err}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(catch_panic(|| 7), Ok(7));
        let v: Vec<u32> = Vec::new();
        let err = catch_panic(|| v[3]).unwrap_err();
        assert!(err.contains("index out of bounds"), "{err}");
    }
}

/// FNV-1a (64-bit, hex) of bytes: a saved model's fingerprint of its weights file.
pub fn fnv(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// [`fnv`] of a model's weights file (at most [`MAX_WEIGHTS_BYTES`]).
pub fn file_fnv(path: &Path) -> crate::core::error::Result<String> {
    Ok(fnv(&read_user_file(
        path,
        "weights file",
        MAX_WEIGHTS_BYTES,
    )?))
}
