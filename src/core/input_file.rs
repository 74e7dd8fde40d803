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

/// The largest mesh file read (and any file a mesh names, an OBJ's materials).
pub const MAX_MESH_BYTES: u64 = 512 << 20;

/// The bytes of `path`, if it is a regular file (a link to one is followed) of at most
/// `max` bytes; otherwise an error saying what it is. `what` names the file in the message
/// ("mesh", "robot description").
pub fn read_regular(path: &Path, what: &str, max: u64) -> std::io::Result<Vec<u8>> {
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
    let mut bytes = Vec::with_capacity(meta.len() as usize);
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

/// [`fnv`] of a file.
pub fn file_fnv(path: &Path) -> crate::core::error::Result<String> {
    let bytes = std::fs::read(path).map_err(|e| crate::core::error::Error::io(path, e))?;
    Ok(fnv(&bytes))
}
